// First stage of the tiled GPU cascade: bucket tiles.
//
// A query's first-level candidates in table t are the features of the other
// image in the same bucket of table t. So for one pair, one table and one
// bucket id, every (a, b) of A's bucket x B's bucket is a candidate pair in
// *both* directions, and their Hamming distance is the same both ways. One
// warp takes such a tile: lanes hold 32 features of A's bucket, B's bucket
// is staged in shared memory 32 entries at a time and broadcast, and each
// distance is computed once for both directions (the per-query kernel loaded
// every entry from L2 once per query and direction). By default the 32 x 32
// distances of a tile come from eight single-bit tensor-core products
// (popc(a ^ b) = popc(a) + popc(b) - 2 popc(a & b)) and all lanes share the
// survivors' work; CASHASH_GPU_TILE_KERNEL=popc selects the lane-popcount
// version, kept to compare against.
//
// What a tile keeps: every candidate within tau, de-duplicated across tables
// exactly as cascade_hashing.h says (a candidate counts only in the first
// table where the two share a bucket), is appended as a key
// (distance << 24 | other feature) to the candidate list of *both* features
// for this table. Lists are per (feature, table): a feature lies in exactly
// one bucket of each table, so exactly one warp ever writes its list of that
// table, and slots are plain counters of that warp: no global atomics (the
// first tensor-core version reserved slots of per-feature lists with global
// atomic adds, and 39 % of its stall samples waited for their return). A
// list that would exceed its capacity keeps counting (saturating at 255) and
// its feature is answered by the per-query kernel instead; the selection
// kernel (cascade_match_kernels.cuh) ranks the others.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "impl/cascade_match_kernels.cuh"

namespace cashash {
namespace cuda {

// Candidate lists of one batch of pairs. Feature f of side A of task k has
// list row `task.list_offset + f`, feature f of side B row
// `task.list_offset + task.a.num_features + f`; row r and table t own
// keys[(r * num_tables + t) * kTableListCapacity ...] and
// counts[r * num_tables + t] (zeroed before the tile launch).
struct CandidateLists {
  uint32_t* keys = nullptr;
  uint8_t* counts = nullptr;
  int num_tables = 0;
};

// Keys per (feature, table) list: one warp-wide load. Real SIFT at 8192
// features per image has ~73 candidates within tau per query over 8 tables
// (~9 per table), so only features in very dense buckets overflow.
constexpr int kTableListCapacity = 32;

// Fills `lists` for every task (one warp per (task, table, bucket)).
// Asynchronous on `stream`.
void LaunchCascadeTiles(const PairTask* tasks, int num_tasks, const MatchParams& params, CandidateLists lists,
                        cudaStream_t stream);

}  // namespace cuda
}  // namespace cashash
