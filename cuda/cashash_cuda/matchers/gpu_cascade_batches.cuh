// The GPU cascade's matching of a chunk of pairs: the pairs are cut into
// batches, each matched by a few launches over all of its pairs; two batches
// alternate on two streams, so that the host turns one batch's results into
// FeatureMatches while the next runs. Results are written by the device
// straight into mapped pinned memory. One job: tasks in, matches out.
// Internal to the GPU cascade matcher.
#pragma once

#include <cuda_runtime.h>

#include <vector>

#include "cashash/base/types.h"
#include "cashash/matching/matching_options.h"
#include "cashash_cuda/matchers/gpu_epipolar_guides.cuh"
#include "cashash_cuda/matchers/gpu_memory_books.cuh"
#include "cashash_cuda/matching/cascade_matcher.cuh"
#include "cashash_cuda/utils/device_memory.cuh"

namespace cashash {
namespace cuda {

// Scratch and result buffers of one in-flight batch.
struct BatchSlot {
  cudaStream_t stream = nullptr;
  cudaEvent_t done = nullptr;
  DeviceBuffer tasks;        // PairTask[]
  DeviceBuffer best;         // int32 per forward query
  DeviceBuffer cursor;       // one uint32
  DeviceBuffer list_keys;    // tiled kernels: kCandidateListCapacity uint32 per list row
  DeviceBuffer list_counts;  // tiled kernels: uint32 per list row
  DeviceBuffer guides;       // guided matching: EpipolarGuideDevice per task
  DeviceBuffer big_buckets;  // tiled kernels with a second pass: one BigBucketBlock
  PinnedBuffer host_tasks;   // staging of PairTask[]
  PinnedBuffer host_guides;  // staging of EpipolarGuideDevice[]
  size_t guide_capacity = 0;
  PinnedBuffer out;       // mapped: uint2 matches
  PinnedBuffer segments;  // mapped: MatchSegment per task
  size_t task_capacity = 0, query_capacity = 0, row_capacity = 0;
  // What is in flight: the pair index of each task.
  std::vector<size_t> pair_of_task;
  bool busy = false;
};

class GpuCascadeBatches {
 public:
  // Kernels: the bucket tiles (`tiled`) or the per-query kernel. Scratch
  // from `resources`, counted in `books` (both outlive it). The device must
  // be current.
  GpuCascadeBatches(const SiftMatchingOptions& sift_options, const CasHashOptions& options, int device, bool tiled,
                    GpuResources* resources, GpuMemoryBooks* books);
  ~GpuCascadeBatches();
  GpuCascadeBatches(const GpuCascadeBatches&) = delete;
  GpuCascadeBatches& operator=(const GpuCascadeBatches&) = delete;

  // The first slot's stream, idle between calls: where images are uploaded
  // and hashed, and exact matching runs.
  cudaStream_t first_stream() const { return slots_[0].stream; }

  // Matches tasks[t] into (*results)[pair_of_task[t]]; with `guides` (of
  // these tasks), within the epipolar bands.
  void Match(const std::vector<PairTask>& tasks, const std::vector<size_t>& pair_of_task,
             const GpuEpipolarGuides* guides, std::vector<FeatureMatches>* results);

 private:
  size_t ListBytes(size_t rows) const;
  size_t SlotBytes(size_t tasks, size_t queries, size_t rows) const;
  size_t BatchEnd(const std::vector<PairTask>& tasks, size_t start) const;
  void EnsureCapacity(BatchSlot* slot, size_t num_tasks, size_t queries, size_t rows);
  void StageGuides(BatchSlot* slot, const GpuEpipolarGuides& guides, size_t start, size_t end);
  void Launch(BatchSlot* slot, const std::vector<PairTask>& all_tasks, const std::vector<size_t>& pair_of_task,
              const GpuEpipolarGuides* guides, size_t start, size_t end);
  void Harvest(BatchSlot* slot, std::vector<FeatureMatches>* results);

  const SiftMatchingOptions sift_options_;
  const CasHashOptions options_;
  const int device_;
  const bool tiled_;
  const int list_capacity_;
  GpuResources* resources_;
  GpuMemoryBooks* books_;
  int sm_count_ = 1;
  int grid_size_ = 1;
  BatchSlot slots_[2];
};

}  // namespace cuda
}  // namespace cashash
