// First stage of the tiled GPU cascade: bucket tiles.
//
// A query's first-level candidates in table t are the features of the other
// image in the same bucket of table t. So for one pair, one table and one
// bucket id, every (a, b) of A's bucket x B's bucket is a candidate pair in
// *both* directions, and their Hamming distance is the same both ways. One
// warp takes such a tile: lanes hold 32 features of A's bucket, B's bucket
// is staged in shared memory 32 entries at a time and broadcast, and each
// distance is computed once for both directions (the per-query kernel loaded
// every entry from L2 once per query and direction).
//
// What a tile keeps: for every feature of either side, the keys
// (distance << 24 | other feature) of its candidates within tau in this
// table, de-duplicated across tables exactly as cascade_hashing.h says (a
// candidate counts only in the first table where the two share a bucket).
// At most `capacity` (>= top_k) keys are kept per feature and table: when a
// list is full, a smaller key replaces its largest one. The top_k of a query
// over all tables is then the top_k of the union of its per-table lists,
// which the selection kernel (cascade_match_kernels.cuh) computes.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "impl/cascade_match_kernels.cuh"

namespace cashash {
namespace cuda {

// Per-feature, per-table candidate lists of one batch of pairs. Feature f of
// side A of task k has list row `task.list_offset + f`, feature f of side B
// row `task.list_offset + task.a.num_features + f`; row r, table t owns
// keys[(r * num_tables + t) * capacity ...] and counts[r * num_tables + t]
// (number of keys held, <= capacity; zeroed before the tile launch).
struct CandidateLists {
  uint32_t* keys = nullptr;
  uint8_t* counts = nullptr;
  int capacity = 0;
};

// Keys kept per feature and table for a given top_k.
inline int CandidateListCapacity(int top_k) { return top_k <= 16 ? 16 : 32; }

// Fills `lists` for every task (one warp per (task, table, bucket)).
// Asynchronous on `stream`.
void LaunchCascadeTiles(const PairTask* tasks, int num_tasks, const MatchParams& params, CandidateLists lists,
                        cudaStream_t stream);

}  // namespace cuda
}  // namespace cashash
