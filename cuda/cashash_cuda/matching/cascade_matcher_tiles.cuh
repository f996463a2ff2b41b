// First stage of the tiled GPU cascade: bucket tiles.
//
// A query's first-level candidates in table t are the features of the other
// image in the same bucket of table t. So for one pair, one table and one
// bucket id, every (a, b) of A's bucket x B's bucket is a candidate pair in
// *both* directions, and their Hamming distance is the same both ways. One
// warp takes such a tile: lanes hold 32 features of A's bucket, B's bucket
// is staged in shared memory 32 entries at a time and broadcast, and each
// distance is computed once for both directions (the per-query kernel loaded
// every entry from L2 once per query and direction). The 32 x 32 distances
// of a tile come from eight single-bit tensor-core products
// (popc(a ^ b) = popc(a) + popc(b) - 2 popc(a & b)).
//
// What a tile keeps: every candidate within tau, de-duplicated across tables
// exactly as cascade_hashing.h says (a candidate counts only in the first
// table where the two share a bucket), is appended as a key
// (distance << 24 | other feature) to the candidate list of *both* features.
// A list is append-only and unordered; its slots are reserved with one
// atomic add per lane and staged chunk, so no list is ever searched or
// sorted here. A feature with more candidates than a list holds keeps its
// count (above the capacity) and is answered by the per-query kernel
// instead; the selection kernel (cascade_matcher.cuh) ranks the others.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "cashash_cuda/matching/cascade_matcher.cuh"

namespace cashash {
namespace cuda {

// Candidate lists of one batch of pairs. Feature f of side A of task k has
// list row `task.list_offset + f`, feature f of side B row
// `task.list_offset + task.a.num_features + f`; row r owns
// keys[r * capacity ...] and counts[r] (keys appended; above capacity when
// the list overflowed; zeroed before the tile launch).
struct CandidateLists {
  uint32_t* keys = nullptr;
  uint32_t* counts = nullptr;
  int capacity = 0;
};

// Keys per list. Real SIFT at 8192 features per image has ~44 candidates
// within tau per query on average (8 x 7 tables) with a long tail; 256
// leaves the per-query fallback to the few features in very dense buckets.
constexpr int kCandidateListCapacity = 256;

// Where the first tile pass leaves the rest of the buckets larger than
// first_chunks chunks of 32 A rows, for a second pass of `warps` warps that
// share those chunks out one at a time (all device memory, zeroed by
// LaunchCascadeTiles). entries[i] = (item, its first flattened chunk);
// header = entries << 32 | chunks queued; a bucket that finds the queue
// full is done by its own warp, and overflow_base stops the second pass
// there. entries == nullptr: no queue, every warp does its whole bucket.
struct BigBucketQueue {
  uint2* entries = nullptr;
  uint32_t capacity = 0;
  unsigned long long* header = nullptr;
  uint32_t* cursor = nullptr;
  uint32_t* overflow_base = nullptr;
  uint32_t first_chunks = 4;
  unsigned warps = 0;
};

// Fills `lists` for every task: one warp per (task, table, bucket), and
// with `big`, the chunks of 32 A rows of large buckets past the first few
// shared out in a second pass. Buckets are far from equal: at 16,384 features and 6 x 10
// bits the largest hold 500-750 features, 24 x 24 tiles for one warp against
// one for a bucket of 16, so a single warp could outlast the rest of the
// launch. Either way the same candidates reach the same (unordered) lists.
// Asynchronous on `stream`.
void LaunchCascadeTiles(const PairTask* tasks, int num_tasks, const MatchParams& params, CandidateLists lists,
                        cudaStream_t stream, BigBucketQueue big = BigBucketQueue());

}  // namespace cuda
}  // namespace cashash
