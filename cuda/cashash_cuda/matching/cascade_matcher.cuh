// Cascade matching of many image pairs per launch: a persistent grid of
// warps walks a queue of (pair, chunk of query features) items; one warp
// answers one query at a time (steps 4 and 5 of cascade_hashing.h) and, with
// cross-check, the reverse query of each forward match right after it; then
// a compaction pass writes the matches.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "cashash_cuda/matching/device_image.cuh"

namespace cashash {
namespace cuda {

// Query features per work item (one warp handles one item).
constexpr int kQueriesPerItem = 16;
// The warp keeps the ranked candidates in one register per lane.
constexpr int kMaxGpuTopK = 32;
// One lane per table when locating a query's buckets.
constexpr int kMaxGpuTables = 32;
// Feature rows share a 32-bit ranking key with the Hamming distance.
constexpr uint32_t kMaxGpuFeatures = 1u << 24;

struct PairTask {
  DeviceImageView a;  // first image of the pair (queries of the forward pass)
  DeviceImageView b;
  uint32_t best_offset = 0;  // start of this pair's a.num_features results
  uint32_t item_begin = 0;   // first work item (ceil(a.n / kQueriesPerItem) items)
  uint32_t list_offset = 0;  // first candidate-list row (tiled path, cascade_matcher_tiles.cuh)
};

struct MatchParams {
  int num_tables = 0;
  int bits_per_table = 0;
  int tau = 0;
  int top_k = 0;
  float max_ratio = 0.f;
  float max_distance = 0.f;
  // Lowest / highest bit of every b-bit bucket field of a signature (the
  // fields past num_tables included), for the duplicate test.
  uint64_t field_low_bits = 0;
  uint64_t field_high_bits = 0;
};

// Segment of one pair's matches in the output: [begin, begin + count).
struct MatchSegment {
  uint32_t begin;
  uint32_t count;
};

// Number of resident blocks of the matching kernels that fill the device.
int CascadeMatchGridSize(int device);

// best[task.best_offset + i] = accepted best match in b of feature i of a, or
// -1; with cross_check, -1 also unless the reverse query of that match gives
// i back (one launch). Asynchronous on `stream`.
void LaunchCascadeMatch(const PairTask* tasks, int num_tasks, uint32_t total_items, const MatchParams& params,
                        bool cross_check, int grid_size, int32_t* best, cudaStream_t stream);

struct CandidateLists;

// The same result from the candidate lists filled by LaunchCascadeTiles: per
// query, the top_k of its lists' keys, then exact distances and the
// decision, with the reverse query fused as above.
void LaunchCascadeSelect(const PairTask* tasks, int num_tasks, uint32_t total_items, const MatchParams& params,
                         const CandidateLists& lists, bool cross_check, int grid_size, int32_t* best,
                         cudaStream_t stream);

// Epipolar guidance of one task (Ga-CasHash stage 2, cascade_matcher.h
// EpipolarGuidance): F (row-major, x2^T F x1 = 0 for x1 in a, x2 in b) and
// where the pixel positions of a's and b's features start in the points
// array passed with it.
struct EpipolarGuideDevice {
  double F[9];
  uint32_t points_a = 0;
  uint32_t points_b = 0;
};

// LaunchCascadeMatch / LaunchCascadeSelect with each query's candidates
// restricted to the band of max_distance pixels around its epipolar line
// (guides[task], points: float2 pixel positions); the band is tested before
// the top_k ranking, as on the CPU.
void LaunchCascadeMatchGuided(const PairTask* tasks, int num_tasks, uint32_t total_items, const MatchParams& params,
                              const EpipolarGuideDevice* guides, const float2* points, double max_distance,
                              bool cross_check, int grid_size, int32_t* best, cudaStream_t stream);
void LaunchCascadeSelectGuided(const PairTask* tasks, int num_tasks, uint32_t total_items, const MatchParams& params,
                               const CandidateLists& lists, const EpipolarGuideDevice* guides, const float2* points,
                               double max_distance, bool cross_check, int grid_size, int32_t* best,
                               cudaStream_t stream);

// Writes each task's surviving matches (point2D_idx1, point2D_idx2) in
// ascending idx1 into out (device-visible, e.g. mapped host memory) and its
// segment into segments[task]; *cursor (device memory, zeroed before)
// hands out space. Asynchronous on `stream`.
void LaunchCompactMatches(const PairTask* tasks, int num_tasks, const int32_t* best, uint2* out,
                          MatchSegment* segments, uint32_t* cursor, cudaStream_t stream);

}  // namespace cuda
}  // namespace cashash
