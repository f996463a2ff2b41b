// Kernels of cascade_matcher_tiles.cuh.
//
// Cost model (8192 features per image, 8 tables x 7 bits, tau 43, real
// SIFT): a pair has ~6M (a, b, table) candidate pairs in ~8k tiles of
// 32 x 32, ~10 % of them within tau (~600k survivors, each appended to two
// lists). Per tile: eight single-bit tensor-core products give the 1024
// distances, ~100 lane instructions turn them into one 32-bit tau mask per
// A row, and the survivors are queued so that all 32 lanes share their work
// (duplicate test, exact distance, ranks, two appends).
//
// Rules the design keeps (docs/gpu_cascade_design.md has the figures):
// candidate lists are append-only (keeping them sorted makes list upkeep
// the main cost); the tau test runs on tensor-core tiles and the warp
// shares each survivor's work, since one lane per A row leaves the warp
// waiting on its busiest lane; the lists are per query, not per (feature,
// table): fixed-size per-table lists overflow on dense buckets, and their
// fallback costs more than the atomics it saves.
#include "cashash_cuda/matching/cascade_matcher_tiles.cuh"

#include <algorithm>

#include "cashash_cuda/utils/bit_mma.cuh"
#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/warp_primitives.cuh"

namespace cashash {
namespace cuda {
namespace {

// One warp per block: tiles differ in size by orders of magnitude, and a
// block's resources are only freed when its last warp ends, so multi-warp
// blocks hold the SMs for their slowest tile; independent one-warp blocks
// keep them full.
constexpr int kTileThreads = 32;

// Survivors queued per round; a 32 x 32 tile has at most 1024.
constexpr int kQueueCapacity = 512;

// Shared memory of the warp (~4.3 KB, so 32 one-warp blocks fit an SM).
struct TileScratch {
  // Staged A rows (one chunk of 32 of A's bucket) and B entries.
  uint4 code_a[32];
  uint64_t signature_a[32];
  uint32_t index_a[32];
  uint32_t pop_a[32];   // popcount of the code; 255 past the bucket's end
  uint32_t kept_a[32];  // survivors of the row in this round (then: its first list slot)
  uint4 code_b[32];
  uint64_t signature_b[32];
  uint32_t index_b[32];
  uint32_t pop_b[32];
  uint32_t kept_b[32];
  // Queued survivors: row | col << 5 on entry; after the duplicate test
  // row | col << 5 | rank in row << 10 | rank in col << 15 | distance << 20,
  // or kDropped.
  uint32_t queue[kQueueCapacity];
};
constexpr uint32_t kDropped = 0xffffffffu;

__device__ __forceinline__ uint32_t Popc128(uint4 v) { return __popc(v.x) + __popc(v.y) + __popc(v.z) + __popc(v.w); }

// One (task, table, bucket): where its two buckets lie and what the
// duplicate test needs.
struct BucketView {
  const BucketEntry* entries_a;
  const BucketEntry* entries_b;
  uint32_t a_begin, a_end, b_begin, b_end;
  size_t rows_a, rows_b;    // first list rows of the pair's sides
  uint64_t below;           // signature bits of the tables before this one
  uint64_t high_from_t;
};

__device__ __forceinline__ BucketView ViewBucket(const PairTask* tasks, const MatchParams& params, uint32_t item) {
  const int bits = params.bits_per_table;
  const uint32_t buckets = 1u << bits;
  const uint32_t per_task = static_cast<uint32_t>(params.num_tables) * buckets;
  const uint32_t task_index = item / per_task;
  const uint32_t table = (item - task_index * per_task) >> bits;
  const uint32_t bucket = item & (buckets - 1);
  const PairTask& task = tasks[task_index];
  BucketView v;
  const uint32_t* offsets_a = task.a.offsets + table * (buckets + 1) + bucket;
  const uint32_t* offsets_b = task.b.offsets + table * (buckets + 1) + bucket;
  v.a_begin = offsets_a[0];
  v.a_end = offsets_a[1];
  v.b_begin = offsets_b[0];
  v.b_end = offsets_b[1];
  v.entries_a = task.a.entries + size_t(table) * task.a.num_features;
  v.entries_b = task.b.entries + size_t(table) * task.b.num_features;
  v.rows_a = task.list_offset;
  v.rows_b = size_t(task.list_offset) + task.a.num_features;
  // Duplicate test (see EntryKey in cascade_matcher.cu): fields of the
  // tables before this one must all differ.
  v.below = (uint64_t{1} << (table * bits)) - 1;
  v.high_from_t = params.field_high_bits & ~v.below;
  return v;
}

// Stages A's rows a0 .. a0 + 31 of the bucket in the warp's scratch (rows
// past a_end get an empty code and pop 255, so no column is within tau).
__device__ __forceinline__ void StageRowsA(TileScratch& s, const BucketView& v, uint32_t a0, unsigned lane) {
  const bool valid = a0 + lane < v.a_end;
  const uint4* entry = reinterpret_cast<const uint4*>(v.entries_a + min(a0 + lane, v.a_end - 1));
  const uint4 code = valid ? __ldg(entry) : make_uint4(0, 0, 0, 0);
  const uint4 meta = __ldg(entry + 1);
  s.code_a[lane] = code;
  s.signature_a[lane] = uint64_t(meta.y) << 32 | meta.x;
  s.index_a[lane] = meta.z;
  s.pop_a[lane] = valid ? Popc128(code) : 255u;
}

// Stages B's entries b0 .. b0 + 31 of the bucket, as StageRowsA. The
// previous chunk's queue passes read the staged entries until the
// __syncwarp between the loads and the stores.
__device__ __forceinline__ void StageColumnsB(TileScratch& s, const BucketView& v, uint32_t b0, unsigned lane) {
  const bool valid = b0 + lane < v.b_end;
  const uint4* entry = reinterpret_cast<const uint4*>(v.entries_b + min(b0 + lane, v.b_end - 1));
  const uint4 code = valid ? __ldg(entry) : make_uint4(0, 0, 0, 0);
  const uint4 meta = __ldg(entry + 1);
  __syncwarp();  // the previous chunk's queue passes are done with these
  s.code_b[lane] = code;
  s.signature_b[lane] = uint64_t(meta.y) << 32 | meta.x;
  s.index_b[lane] = meta.z;
  s.pop_b[lane] = valid ? Popc128(code) : 255u;
}

// This lane's A fragments (rows mi * 16 + g + 8h, word t) and the
// thresholds of its four rows: within tau <=> 2 c - pop_b >= pop_a - tau.
__device__ __forceinline__ void LoadFragmentsA(const TileScratch& s, unsigned g, unsigned t, int tau,
                                               uint32_t (&frag_a)[4], int (&row_limit)[4]) {
  const uint32_t* words_a = reinterpret_cast<const uint32_t*>(s.code_a);
#pragma unroll
  for (int k = 0; k < 4; ++k) {
    const unsigned row = (k >> 1) * 16 + g + (k & 1) * 8;
    frag_a[k] = words_a[row * 4 + t];
    row_limit[k] = static_cast<int>(s.pop_a[row]) - tau;
  }
}

// The tau mask of row `lane` of the staged tile: bit c set when (row, column
// c) is within tau. Eight single-bit tensor-core products give the
// distances of this lane's rows and columns 2t, 2t + 1 of each n-tile; the
// shuffles gather whole rows.
__device__ __forceinline__ uint32_t TauRowMask(const TileScratch& s, const uint32_t (&frag_a)[4],
                                               const int (&row_limit)[4], unsigned g, unsigned t, unsigned lane) {
  const uint32_t* words_b = reinterpret_cast<const uint32_t*>(s.code_b);
  uint32_t mask[4] = {0, 0, 0, 0};
#pragma unroll
  for (int ni = 0; ni < 4; ++ni) {
    const uint32_t frag_b = words_b[(ni * 8 + g) * 4 + t];
    const int pop0 = static_cast<int>(s.pop_b[ni * 8 + 2 * t]);
    const int pop1 = static_cast<int>(s.pop_b[ni * 8 + 2 * t + 1]);
#pragma unroll
    for (int mi = 0; mi < 2; ++mi) {
      int d[4];
      BitAndPopcMma16x8x128(frag_a[mi * 2], frag_a[mi * 2 + 1], frag_b, d);
      const uint32_t bit0 = 1u << (ni * 8), bit1 = 2u << (ni * 8);
      mask[mi * 2] |= (2 * d[0] - pop0 >= row_limit[mi * 2] ? bit0 : 0u) |
                      (2 * d[1] - pop1 >= row_limit[mi * 2] ? bit1 : 0u);
      mask[mi * 2 + 1] |= (2 * d[2] - pop0 >= row_limit[mi * 2 + 1] ? bit0 : 0u) |
                          (2 * d[3] - pop1 >= row_limit[mi * 2 + 1] ? bit1 : 0u);
    }
  }
  // Whole rows: the four lanes of a group hold disjoint columns.
#pragma unroll
  for (int k = 0; k < 4; ++k) {
    mask[k] <<= 2 * t;
    mask[k] |= __shfl_xor_sync(kFullWarpMask, mask[k], 1);
    mask[k] |= __shfl_xor_sync(kFullWarpMask, mask[k], 2);
  }
  // Lane r takes row r = 8k + g' from group g' (k = r / 8).
  const unsigned source = (lane & 7u) << 2;
  const uint32_t m0 = __shfl_sync(kFullWarpMask, mask[0], source);
  const uint32_t m1 = __shfl_sync(kFullWarpMask, mask[1], source);
  const uint32_t m2 = __shfl_sync(kFullWarpMask, mask[2], source);
  const uint32_t m3 = __shfl_sync(kFullWarpMask, mask[3], source);
  const unsigned k = lane >> 3;
  return k == 0 ? m0 : k == 1 ? m1 : k == 2 ? m2 : m3;
}

// Queue positions in row order: this lane's row's survivors take positions
// first .. first + popc(row_mask) - 1 of `total`.
__device__ __forceinline__ void QueuePositions(uint32_t row_mask, unsigned lane, uint32_t* first_out,
                                               uint32_t* total_out) {
  const uint32_t count = __popc(row_mask);
  uint32_t first = count;
#pragma unroll
  for (int d = 1; d < 32; d <<= 1) {
    const uint32_t o = __shfl_up_sync(kFullWarpMask, first, d);
    if (lane >= static_cast<unsigned>(d)) first += o;
  }
  *total_out = __shfl_sync(kFullWarpMask, first, 31);
  *first_out = first - count;
}

// Queues this lane's row's survivors whose positions fall in the round
// [round, round + in_round), as row | col << 5.
__device__ __forceinline__ void QueueRound(TileScratch& s, uint32_t row_mask, uint32_t first, uint32_t round,
                                           uint32_t in_round, unsigned lane) {
  uint32_t position = first, m = row_mask;
  while (m != 0 && position < round + in_round) {
    const uint32_t col = __ffs(m) - 1;
    m &= m - 1;
    if (position >= round) s.queue[position - round] = lane | col << 5;
    ++position;
  }
}

// Duplicate test, distance and ranks of the queued survivors, 32 per step:
// each entry becomes row | col << 5 | rank in row << 10 | rank in col << 15
// | distance << 20, or kDropped.
__device__ __forceinline__ void TestQueued(TileScratch& s, const BucketView& v, const MatchParams& params,
                                           uint32_t in_round, unsigned lane) {
  for (uint32_t p = lane; p < in_round; p += 32) {
    const uint32_t e = s.queue[p];
    const uint32_t row = e & 31u, col = (e >> 5) & 31u;
    const uint64_t x_sig = ((s.signature_a[row] ^ s.signature_b[col]) & v.below) | v.high_from_t;
    uint32_t out = kDropped;
    if (((x_sig - params.field_low_bits) & ~x_sig & params.field_high_bits) == 0) {
      const uint4 x = s.code_a[row], y = s.code_b[col];
      const uint32_t distance = __popc(x.x ^ y.x) + __popc(x.y ^ y.y) + __popc(x.z ^ y.z) + __popc(x.w ^ y.w);
      const uint32_t rank_a = atomicAdd(&s.kept_a[row], 1u);
      const uint32_t rank_b = atomicAdd(&s.kept_b[col], 1u);
      out = row | col << 5 | rank_a << 10 | rank_b << 15 | distance << 20;
    }
    s.queue[p] = out;
  }
}

// One list reservation per row and per column of the round: kept_a and
// kept_b turn from counts into the first reserved slot.
__device__ __forceinline__ void ReserveListSlots(TileScratch& s, const BucketView& v, const CandidateLists& lists,
                                                 unsigned lane) {
  const uint32_t kept_a = s.kept_a[lane], kept_b = s.kept_b[lane];
  if (kept_a > 0) s.kept_a[lane] = atomicAdd(lists.counts + v.rows_a + s.index_a[lane], kept_a);
  if (kept_b > 0) s.kept_b[lane] = atomicAdd(lists.counts + v.rows_b + s.index_b[lane], kept_b);
}

// Appends each kept survivor to its A row's and its B column's list (what
// falls past a list's capacity is left out).
__device__ __forceinline__ void AppendQueued(const TileScratch& s, const BucketView& v, const CandidateLists& lists,
                                             uint32_t capacity, uint32_t in_round, unsigned lane) {
  for (uint32_t p = lane; p < in_round; p += 32) {
    const uint32_t e = s.queue[p];
    if (e == kDropped) continue;
    const uint32_t row = e & 31u, col = (e >> 5) & 31u;
    const uint32_t rank_a = (e >> 10) & 31u, rank_b = (e >> 15) & 31u, distance = e >> 20;
    const uint32_t index_a = s.index_a[row], index_b = s.index_b[col];
    const uint32_t slot_a = s.kept_a[row] + rank_a, slot_b = s.kept_b[col] + rank_b;
    if (slot_a < capacity) lists.keys[(v.rows_a + index_a) * capacity + slot_a] = distance << 24 | index_b;
    if (slot_b < capacity) lists.keys[(v.rows_b + index_b) * capacity + slot_b] = distance << 24 | index_a;
  }
}

// A's rows a0 .. a0 + 31 (those before a_end) against all of B's bucket:
// per chunk of 32 B entries, the tau masks, then rounds of queued survivors
// (test, reserve, append). The steps are inlined helpers, so the warp's A
// fragments and row limits stay in registers across the whole B sweep; the
// __syncwarp calls here order the steps' use of the shared scratch.
// s.kept_a and s.kept_b are zero on entry and on return.
__device__ __forceinline__ void TileChunk(TileScratch& s, const BucketView& v, uint32_t a0, const MatchParams& params,
                                          const CandidateLists& lists) {
  const unsigned lane = LaneId();
  const unsigned g = lane >> 2, t = lane & 3u;  // MMA fragment coordinates
  const uint32_t capacity = static_cast<uint32_t>(lists.capacity);
  const int tau = min(params.tau, 128);
  __syncwarp();
  StageRowsA(s, v, a0, lane);
  __syncwarp();
  uint32_t frag_a[4];
  int row_limit[4];
  LoadFragmentsA(s, g, t, tau, frag_a, row_limit);

  for (uint32_t b0 = v.b_begin; b0 < v.b_end; b0 += 32) {
    StageColumnsB(s, v, b0, lane);
    __syncwarp();
    const uint32_t row_mask = TauRowMask(s, frag_a, row_limit, g, t, lane);
    uint32_t first, total;
    QueuePositions(row_mask, lane, &first, &total);
    for (uint32_t round = 0; round < total; round += kQueueCapacity) {
      const uint32_t in_round = min(total - round, static_cast<uint32_t>(kQueueCapacity));
      QueueRound(s, row_mask, first, round, in_round, lane);
      __syncwarp();
      TestQueued(s, v, params, in_round, lane);
      __syncwarp();
      ReserveListSlots(s, v, lists, lane);
      __syncwarp();
      AppendQueued(s, v, lists, capacity, in_round, lane);
      __syncwarp();
      s.kept_a[lane] = 0;
      s.kept_b[lane] = 0;
    }
  }
}

// First pass: one warp per (task, table, bucket) (see LaunchCascadeTiles).
// With a queue (big.entries), the warp takes its bucket's first
// big.first_chunks chunks of A and queues the rest of a larger bucket as
// (item, first flattened chunk) for the second pass, or, if the queue is
// full, does the rest itself.
__global__ void __launch_bounds__(kTileThreads) CascadeTileKernel(const PairTask* tasks, uint32_t total_items,
                                                                  MatchParams params, CandidateLists lists,
                                                                  BigBucketQueue big) {
  __shared__ TileScratch s;
  const unsigned lane = LaneId();
  if (blockIdx.x >= total_items) return;
  const uint32_t item = blockIdx.x;
  const BucketView v = ViewBucket(tasks, params, item);
  if (v.a_begin >= v.a_end || v.b_begin == v.b_end) return;
  uint32_t a_limit = v.a_end;
  bool rest_here = false;  // the queue was full: this warp does the rest too
  if (big.entries != nullptr && v.a_end - v.a_begin > 32u * big.first_chunks) {
    a_limit = v.a_begin + 32u * big.first_chunks;
    {
      unsigned long long old = 0;
      const uint32_t rest = (v.a_end - a_limit + 31) / 32;
      if (lane == 0) {
        old = atomicAdd(big.header, (1ull << 32) | rest);
        const uint32_t index = static_cast<uint32_t>(old >> 32);
        if (index < big.capacity) {
          big.entries[index] = make_uint2(item, static_cast<uint32_t>(old));
        } else if (index == big.capacity) {
          *big.overflow_base = static_cast<uint32_t>(old);  // the second pass stops here
        }
      }
      old = __shfl_sync(kFullWarpMask, old, 0);
      rest_here = static_cast<uint32_t>(old >> 32) >= big.capacity;
    }
  }

  s.kept_a[lane] = 0;
  s.kept_b[lane] = 0;
  for (uint32_t a0 = v.a_begin; a0 < a_limit; a0 += 32u) TileChunk(s, v, a0, params, lists);
  if (rest_here) {
    for (uint32_t a0 = a_limit; a0 < v.a_end; a0 += 32) TileChunk(s, v, a0, params, lists);
  }
}

// Second pass: every warp takes the queued chunks one at a time (a chunk of
// 32 A rows against all of its B bucket) until none is left, so that a
// bucket of hundreds of rows is spread over as many warps.
__global__ void __launch_bounds__(kTileThreads) CascadeBigBucketKernel(const PairTask* tasks, MatchParams params,
                                                                       CandidateLists lists, BigBucketQueue big) {
  __shared__ TileScratch s;
  const unsigned lane = LaneId();
  const unsigned long long header = *big.header;
  const uint32_t count = static_cast<uint32_t>(header >> 32);
  const uint32_t n = min(count, big.capacity);
  const uint32_t total = count > big.capacity ? *big.overflow_base : static_cast<uint32_t>(header);
  s.kept_a[lane] = 0;
  s.kept_b[lane] = 0;
  for (;;) {
    uint32_t k = 0;
    if (lane == 0) k = atomicAdd(big.cursor, 1u);
    k = __shfl_sync(kFullWarpMask, k, 0);
    if (k >= total) return;
    // The entry whose chunks hold k: the last with first chunk <= k.
    uint32_t lo = 0, hi = n;
    while (hi - lo > 1) {
      const uint32_t mid = (lo + hi) / 2;
      if (big.entries[mid].y <= k) lo = mid; else hi = mid;
    }
    const uint2 entry = big.entries[lo];
    const BucketView v = ViewBucket(tasks, params, entry.x);
    const uint32_t a0 = v.a_begin + 32u * (big.first_chunks + (k - entry.y));
    TileChunk(s, v, a0, params, lists);
  }
}

}  // namespace

void LaunchCascadeTiles(const PairTask* tasks, int num_tasks, const MatchParams& params, CandidateLists lists,
                        cudaStream_t stream, BigBucketQueue big) {
  if (num_tasks == 0) return;
  const uint64_t blocks = uint64_t(num_tasks) * params.num_tables * (uint64_t{1} << params.bits_per_table);
  if (big.entries != nullptr) {
    // header (count << 32 | chunks) and the second pass's cursor
    CUDA_CHECK(cudaMemsetAsync(big.header, 0, sizeof(unsigned long long), stream));
    CUDA_CHECK(cudaMemsetAsync(big.cursor, 0, sizeof(uint32_t), stream));
  }
  CascadeTileKernel<<<static_cast<unsigned>(blocks), kTileThreads, 0, stream>>>(
      tasks, static_cast<uint32_t>(blocks), params, lists, big);
  CUDA_CHECK_LAUNCH();
  if (big.entries != nullptr) {
    CascadeBigBucketKernel<<<big.warps, kTileThreads, 0, stream>>>(tasks, params, lists, big);
    CUDA_CHECK_LAUNCH();
  }
}

}  // namespace cuda
}  // namespace cashash
