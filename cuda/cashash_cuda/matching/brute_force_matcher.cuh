// Exact brute-force SIFT matching on the GPU: integer dot products on the
// tensor cores (u8 x u8 -> s32 mma, so every dot is exact), best and second
// best per query row fused into the same kernel, then COLMAP's angle ratio /
// max_distance test and cross-check, compacted into per-pair match lists.
// Same results as the CPU brute force (src/cashash/matching/brute_force_matcher.h).
//
// Plain C++ header (no device code): usable from .cc and .cu files.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>
#include <utility>
#include <vector>

#include "cashash/matching/matching_options.h"
#include "cashash/base/types.h"
#include "cashash_cuda/utils/gpu_resources.h"

namespace cashash {
namespace cuda {

// One best-two search, all pointers on the device. For each row i of a
// (n_a x 128 uint8, row-major) among the rows of b (n_b x 128):
//   best_dot[i]   = largest integer dot product (0 when n_b == 0),
//   best_idx[i]   = lowest row of b reaching it, -1 when best_dot is 0,
//   second_dot[i] = second largest dot of the multiset (0 when n_b < 2),
// exactly as BestTwo of the CPU matcher.
// live_rows, when set, is a device count written by earlier work on the
// stream (the gathered rows of a reverse search): only min(n_a,
// *live_rows) rows are searched, and n_a is the capacity the launch is
// sized for.
struct BestTwoProblem {
  const uint8_t* a = nullptr;
  const uint8_t* b = nullptr;
  int* best_dot = nullptr;
  int* second_dot = nullptr;
  int* best_idx = nullptr;
  int n_a = 0;
  int n_b = 0;
  const int* live_rows = nullptr;
};

// The rows of image 2 that the cross-check needs: those that are the
// accepted best of some row of image 1. Their descriptors are copied in
// ascending order to `gathered` (n2 x 128 capacity, 16-byte aligned),
// slot[j] receives row j's position there or -1, and num_gathered their
// count. Only these rows are searched in the reverse direction: a row of
// image 2 that no accepted forward match names cannot pass the cross-check,
// and a row's best two depend on that row alone, so the matches are those
// of the full reverse search.
struct HitGatherProblem {
  const int* best_dot12 = nullptr;
  const int* second_dot12 = nullptr;
  const int* best_idx12 = nullptr;
  const uint8_t* b = nullptr;
  int* slot = nullptr;
  uint8_t* gathered = nullptr;
  int* num_gathered = nullptr;
  int n1 = 0;
  int n2 = 0;
};

// Final matches of one pair (image 1 rows n1, image 2 rows n2) from the two
// best-two results; all pointers on the device. matches receives up to n1
// (idx1, idx2) uint32 pairs (the layout of FeatureMatch) sorted by idx1 and
// num_matches their count. With slot21 set, the reverse results are those
// of the gathered rows (HitGatherProblem): row j's are at slot21[j].
struct MutualMatchProblem {
  const int* best_dot12 = nullptr;
  const int* second_dot12 = nullptr;
  const int* best_idx12 = nullptr;
  const int* best_dot21 = nullptr;
  const int* second_dot21 = nullptr;
  const int* best_idx21 = nullptr;
  const int* slot21 = nullptr;
  uint32_t* matches = nullptr;
  int* num_matches = nullptr;
  int n1 = 0;
  int n2 = 0;
};

struct MatchThresholds {
  float max_ratio = 0.8f;
  float max_distance = 0.7f;
  bool cross_check = true;
};

// Device-resident descriptors of one image (not owned).
struct DeviceDescriptors {
  const uint8_t* data = nullptr;
  int rows = 0;
};

// Owns the scratch memory of the brute-force kernels on one device and one
// stream. Not thread-safe; use one per stream. Construct with the device
// current.
class BruteForceKernels {
 public:
  // Scratch from `resources` (gpu_resources.h), which must outlive this.
  BruteForceKernels(cudaStream_t stream, GpuResources* resources);
  ~BruteForceKernels();
  BruteForceKernels(const BruteForceKernels&) = delete;
  BruteForceKernels& operator=(const BruteForceKernels&) = delete;

  cudaStream_t stream() const { return stream_; }

  // Enqueues every search in one launch on stream(). Returns at once; the
  // problem list itself may be freed after the call.
  void EnqueueBestTwo(const std::vector<BestTwoProblem>& problems);

  // Enqueues the gathering of every pair's needed image-2 rows in one launch
  // (one block per pair).
  void EnqueueHitGather(const std::vector<HitGatherProblem>& problems, const MatchThresholds& thresholds);

  // Enqueues the acceptance test and compaction of every pair in one launch.
  void EnqueueMutualMatches(const std::vector<MutualMatchProblem>& problems,
                            const MatchThresholds& thresholds);

  // Convenience: matches each pair of device images (both directions, ratio
  // test, optional cross-check) and returns the matches of pair i, sorted by
  // idx1, indexing (first image, second image). Blocks until done. With
  // cross-check, the reverse direction searches only the gathered rows
  // (HitGatherProblem): about half the products when few rows match.
  std::vector<FeatureMatches> MatchPairs(
      const std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>>& pairs,
      const MatchThresholds& thresholds);

  // Scratch bytes MatchPairs needs for these images per pair (for batching).
  static size_t MatchPairsScratchBytes(int n1, int n2);

 private:
  // Waits for the stream and copies each pair's compacted matches to the host.
  std::vector<FeatureMatches> CopyMatchesBack(const std::vector<MutualMatchProblem>& mutual,
                                              const int* device_counts);

  struct Scratch;
  cudaStream_t stream_ = nullptr;
  GpuResources* resources_ = nullptr;
  Scratch* scratch_ = nullptr;
};

// Matches any number of pairs of device images in batches whose scratch
// stays within `batch_scratch_bytes` (GpuResources::ScratchBytes; a pair
// larger than that goes alone); a pair with an empty image gets no
// matches. Result i belongs to pair i. Blocks until done. Shared by the
// brute-force backend and the cascade's exact rematch.
std::vector<FeatureMatches> MatchPairsInBatches(BruteForceKernels* kernels,
                                                const std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>>& pairs,
                                                const MatchThresholds& thresholds, size_t batch_scratch_bytes);

// COLMAP's thresholds from the matching options (float, as the CPU test).
inline MatchThresholds ToMatchThresholds(const SiftMatchingOptions& options) {
  MatchThresholds t;
  t.max_ratio = static_cast<float>(options.max_ratio);
  t.max_distance = static_cast<float>(options.max_distance);
  t.cross_check = options.cross_check;
  return t;
}

}  // namespace cuda
}  // namespace cashash
