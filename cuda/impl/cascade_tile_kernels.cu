// Kernels of cascade_tile_kernels.cuh.
//
// Cost model (8192 features per image, 8 tables x 7 bits, tau 43, real
// SIFT): a pair has ~8k tiles of 32 x 32 (a, b, table) candidates, ~6M in
// all, of which ~10 % are within tau (~600k survivors, each appended to two
// lists). Per tile: eight single-bit tensor-core products give the 1024
// distances, ~100 lane instructions turn them into one 32-bit tau mask per A
// row, and the survivors are queued so that all 32 lanes share their work
// (duplicate test, exact distance, two appends). History (H100/H200, same
// benchmark): per-table sorted lists kept by replacing the largest key spent
// most of the time on list upkeep; append-only lists with a lane per A row
// and 32 x 32 lane popcounts reached 26.5k pairs/s on the H200, the tensor-
// core tiles 28.5k, still waiting on global atomics that reserved list
// slots; these per-(feature, table) lists need none.
#include "impl/cascade_tile_kernels.cuh"

#include "utils/bit_mma.cuh"
#include "utils/cuda_check.cuh"
#include "utils/warp_primitives.cuh"

namespace cashash {
namespace cuda {
namespace {

// One warp per block: tiles differ in size by orders of magnitude, and a
// block's resources are only freed when its last warp ends, so independent
// one-warp blocks keep the SMs full where 8-warp blocks left them at 16 %
// occupancy (measured).
constexpr int kTileThreads = 32;

// Survivors queued per round; a 32 x 32 tile has at most 1024.
constexpr int kQueueCapacity = 512;

// Shared memory of the warp (~4.4 KB, so 32 one-warp blocks fit an SM).
struct TileScratch {
  // Staged A rows (one chunk of 32 of A's bucket) and B entries.
  uint4 code_a[32];
  uint64_t signature_a[32];
  uint32_t index_a[32];
  uint32_t pop_a[32];   // popcount of the code; 255 past the bucket's end
  uint32_t kept_a[32];  // keys appended to the row's list so far (this table)
  uint4 code_b[32];
  uint64_t signature_b[32];
  uint32_t index_b[32];
  uint32_t pop_b[32];
  uint32_t kept_b[32];  // keys for the entry in this round
  uint32_t base_b[32];  // the entry's list length before this round
  // Queued survivors: row | col << 5 on entry; after the duplicate test
  // row | col << 5 | rank in col << 10 | min(slot in row, 63) << 15 |
  // distance << 21, or kDropped.
  uint32_t queue[kQueueCapacity];
};
constexpr uint32_t kDropped = 0xffffffffu;

__device__ __forceinline__ uint32_t Popc128(uint4 v) { return __popc(v.x) + __popc(v.y) + __popc(v.z) + __popc(v.w); }

__global__ void __launch_bounds__(kTileThreads) CascadeTileKernel(const PairTask* tasks, uint32_t total_items,
                                                                  MatchParams params, CandidateLists lists) {
  __shared__ TileScratch s;
  const unsigned lane = LaneId();
  const unsigned g = lane >> 2, t = lane & 3u;  // MMA fragment coordinates
  const uint32_t item = blockIdx.x;
  if (item >= total_items) return;

  const int bits = params.bits_per_table;
  const uint32_t buckets = 1u << bits;
  const uint32_t num_tables = static_cast<uint32_t>(params.num_tables);
  const uint32_t per_task = num_tables * buckets;
  const uint32_t task_index = item / per_task;
  const uint32_t table = (item - task_index * per_task) >> bits;
  const uint32_t bucket = item & (buckets - 1);
  const PairTask& task = tasks[task_index];

  const uint32_t* offsets_a = task.a.offsets + table * (buckets + 1) + bucket;
  const uint32_t* offsets_b = task.b.offsets + table * (buckets + 1) + bucket;
  const uint32_t a_begin = offsets_a[0], a_end = offsets_a[1];
  const uint32_t b_begin = offsets_b[0], b_end = offsets_b[1];
  if (a_begin == a_end || b_begin == b_end) return;

  const BucketEntry* entries_a = task.a.entries + size_t(table) * task.a.num_features;
  const BucketEntry* entries_b = task.b.entries + size_t(table) * task.b.num_features;
  // List (row, table) of row r starts at key (r * num_tables + table) * capacity.
  const size_t lists_a = size_t(task.list_offset) * num_tables + table;
  const size_t lists_b = (size_t(task.list_offset) + task.a.num_features) * num_tables + table;
  constexpr uint32_t kCapacity = kTableListCapacity;
  const int tau = min(params.tau, 128);
  const uint64_t below = (uint64_t{1} << (table * bits)) - 1;
  const uint64_t high_from_t = params.field_high_bits & ~below;

  s.kept_b[lane] = 0;
  for (uint32_t a0 = a_begin; a0 < a_end; a0 += 32) {
    __syncwarp();
    const bool row_valid = a0 + lane < a_end;
    {
      const uint4* entry = reinterpret_cast<const uint4*>(entries_a + min(a0 + lane, a_end - 1));
      const uint4 code = row_valid ? __ldg(entry) : make_uint4(0, 0, 0, 0);
      const uint4 meta = __ldg(entry + 1);
      s.code_a[lane] = code;
      s.signature_a[lane] = uint64_t(meta.y) << 32 | meta.x;
      s.index_a[lane] = meta.z;
      s.pop_a[lane] = row_valid ? Popc128(code) : 255u;
      s.kept_a[lane] = 0;
    }
    __syncwarp();
    // This lane's A fragments (rows mi * 16 + g + 8h, word t) and the
    // thresholds of its four rows: within tau <=> 2 c - pop_b >= pop_a - tau.
    const uint32_t* words_a = reinterpret_cast<const uint32_t*>(s.code_a);
    uint32_t frag_a[4];
    int row_limit[4];
#pragma unroll
    for (int k = 0; k < 4; ++k) {
      const unsigned row = (k >> 1) * 16 + g + (k & 1) * 8;
      frag_a[k] = words_a[row * 4 + t];
      row_limit[k] = static_cast<int>(s.pop_a[row]) - tau;
    }

    for (uint32_t b0 = b_begin; b0 < b_end; b0 += 32) {
      const bool col_valid = b0 + lane < b_end;
      uint32_t list_b = 0;  // this lane's B entry: its list length (this table) before the step
      {
        const uint4* entry = reinterpret_cast<const uint4*>(entries_b + min(b0 + lane, b_end - 1));
        const uint4 code = col_valid ? __ldg(entry) : make_uint4(0, 0, 0, 0);
        const uint4 meta = __ldg(entry + 1);
        // Only this warp writes the entry's list of this table: after the
        // first chunk of A rows its length is this lane's own earlier store.
        // Issued now, used only after the tile's survivors are ranked.
        if (a0 != a_begin && col_valid) list_b = lists.counts[lists_b + size_t(meta.z) * num_tables];
        __syncwarp();  // the previous chunk's queue passes are done with these
        s.code_b[lane] = code;
        s.signature_b[lane] = uint64_t(meta.y) << 32 | meta.x;
        s.index_b[lane] = meta.z;
        s.pop_b[lane] = col_valid ? Popc128(code) : 255u;
      }
      __syncwarp();

      // Tau masks: bit c of mask[k] set when (row k of this lane, column c)
      // is within tau, for this lane's columns 2t, 2t + 1 of each n-tile
      // (shifted into place below).
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
      const uint32_t row_mask = k == 0 ? m0 : k == 1 ? m1 : k == 2 ? m2 : m3;

      // Queue positions in row order.
      const uint32_t count = __popc(row_mask);
      uint32_t first = count;
#pragma unroll
      for (int d = 1; d < 32; d <<= 1) {
        const uint32_t o = __shfl_up_sync(kFullWarpMask, first, d);
        if (lane >= static_cast<unsigned>(d)) first += o;
      }
      const uint32_t total = __shfl_sync(kFullWarpMask, first, 31);
      first -= count;

      for (uint32_t round = 0; round < total; round += kQueueCapacity) {
        const uint32_t in_round = min(total - round, static_cast<uint32_t>(kQueueCapacity));
        if (total <= static_cast<uint32_t>(kQueueCapacity)) {
          // Common case: one round, no position checks.
          uint32_t position = first;
          for (uint32_t m = row_mask; m != 0; m &= m - 1) s.queue[position++] = lane | (__ffs(m) - 1) << 5;
        } else {
          uint32_t position = first, m = row_mask;
          while (m != 0 && position < round + in_round) {
            const uint32_t col = __ffs(m) - 1;
            m &= m - 1;
            if (position >= round) s.queue[position - round] = lane | col << 5;
            ++position;
          }
        }
        __syncwarp();
        // Duplicate test, distance and ranks, 32 survivors per step.
        for (uint32_t p = lane; p < in_round; p += 32) {
          const uint32_t e = s.queue[p];
          const uint32_t row = e & 31u, col = (e >> 5) & 31u;
          const uint64_t v = ((s.signature_a[row] ^ s.signature_b[col]) & below) | high_from_t;
          uint32_t out = kDropped;
          if (((v - params.field_low_bits) & ~v & params.field_high_bits) == 0) {
            const uint4 x = s.code_a[row], y = s.code_b[col];
            const uint32_t distance = __popc(x.x ^ y.x) + __popc(x.y ^ y.y) + __popc(x.z ^ y.z) + __popc(x.w ^ y.w);
            const uint32_t slot_a = atomicAdd(&s.kept_a[row], 1u);
            const uint32_t rank_b = atomicAdd(&s.kept_b[col], 1u);
            out = row | col << 5 | rank_b << 10 | min(slot_a, 63u) << 15 | distance << 21;
          }
          s.queue[p] = out;
        }
        __syncwarp();
        s.base_b[lane] = list_b;
        list_b += s.kept_b[lane];
        s.kept_b[lane] = 0;
        __syncwarp();
        for (uint32_t p = lane; p < in_round; p += 32) {
          const uint32_t e = s.queue[p];
          if (e == kDropped) continue;
          const uint32_t row = e & 31u, col = (e >> 5) & 31u;
          const uint32_t rank_b = (e >> 10) & 31u, slot_a = (e >> 15) & 63u, distance = e >> 21;
          const uint32_t index_a = s.index_a[row], index_b = s.index_b[col];
          const uint32_t slot_b = s.base_b[col] + rank_b;
          if (slot_a < kCapacity) {
            lists.keys[(lists_a + size_t(index_a) * num_tables) * kCapacity + slot_a] = distance << 24 | index_b;
          }
          if (slot_b < kCapacity) {
            lists.keys[(lists_b + size_t(index_b) * num_tables) * kCapacity + slot_b] = distance << 24 | index_a;
          }
        }
        __syncwarp();
      }
      if (col_valid && total > 0) {
        lists.counts[lists_b + size_t(s.index_b[lane]) * num_tables] = static_cast<uint8_t>(min(list_b, 255u));
      }
    }
    if (row_valid) {
      lists.counts[lists_a + size_t(s.index_a[lane]) * num_tables] = static_cast<uint8_t>(min(s.kept_a[lane], 255u));
    }
  }
}

}  // namespace

void LaunchCascadeTiles(const PairTask* tasks, int num_tasks, const MatchParams& params, CandidateLists lists,
                        cudaStream_t stream) {
  if (num_tasks == 0) return;
  const uint64_t items = uint64_t(num_tasks) * params.num_tables * (uint64_t{1} << params.bits_per_table);
  CascadeTileKernel<<<static_cast<unsigned>(items), kTileThreads, 0, stream>>>(tasks, static_cast<uint32_t>(items),
                                                                               params, lists);
  CUDA_CHECK_LAUNCH();
}

}  // namespace cuda
}  // namespace cashash
