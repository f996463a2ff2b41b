// Kernels of cascade_tile_kernels.cuh.
//
// Cost model (8192 features per image, 8 tables x 7 bits): a query meets
// ~1,100 bucket entries over the tables, so a pair has ~9M (a, b, table)
// candidate pairs. Here each costs one broadcast shared load per 32 of them
// and ~13 lane instructions (4 XOR, 4 POPC, adds, the tau test and a
// predicated append), i.e. ~0.45 warp instructions per candidate pair, both
// directions at once; the per-query kernel spent ~4 per entry and direction.
// Candidates within tau (a few percent) are appended to a per-lane stripe in
// shared memory and written out after each staged chunk, all lanes at once.
#include "impl/cascade_tile_kernels.cuh"

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
constexpr uint32_t kNoLimit = 0xffffffffu;

// Shared memory of the warp: the staged chunk of B's bucket and the current
// 32 rows of A with their lists for this table, the per-lane stripes of
// survivors (entry = chunk position | distance << 8, stored [n][lane] so that
// the lanes' appends hit distinct banks). The lists themselves (32 x capacity keys per side)
// follow in dynamic shared memory: replacing the largest key of a full list
// then costs a few shared loads, where global lists made big buckets wait on
// one L2 round trip per survivor (measured: one tile of a skewed bucket took
// 1.9 ms).
struct TileScratch {
  uint4 code[32];
  uint64_t signature[32];
  uint32_t index[32];
  uint32_t count[32];    // keys seen by the staged B features in this table
  uint32_t limit_b[32];  // a key must be below it to enter the B list
  uint64_t signature_a[32];
  uint32_t index_a[32];
  uint32_t seen_a[32];   // keys seen by the current A rows in this table
  uint32_t limit_a[32];
  uint16_t stripe[33][32];  // one spare row: the branch-free append
};

// Lists in shared memory are stored slot-major ([slot][32 rows]), so that
// one lane per list reads or writes it without bank conflicts.
//
// Largest key of a full list (in-lane).
__device__ __forceinline__ uint32_t ListMax(const uint32_t* lists, int row, int capacity) {
  uint32_t largest = 0;
  for (int s = 0; s < capacity; ++s) largest = max(largest, lists[s * 32 + row]);
  return largest;
}

// In-lane: puts `key` into the full list in place of its largest key when
// smaller, and returns the list's new largest key (keys of a list are unique).
__device__ __forceinline__ uint32_t ReplaceLargest(uint32_t* lists, int row, int capacity, uint32_t key) {
  uint32_t largest = 0, second = 0;
  int at = 0;
  for (int s = 0; s < capacity; ++s) {
    const uint32_t v = lists[s * 32 + row];
    if (v > largest) {
      second = largest;
      largest = v;
      at = s;
    } else if (v > second) {
      second = v;
    }
  }
  if (key >= largest) return largest;
  lists[at * 32 + row] = key;
  return max(second, key);
}

// Copies one list between shared memory (slot-major, this lane's `row`) and
// its global row (`global`, 16-byte aligned), the first `count` keys rounded
// up to whole 16-byte vectors.
template <bool kToGlobal>
__device__ __forceinline__ void CopyList(uint32_t* lists, int row, uint32_t count, uint32_t* global) {
  for (uint32_t s = 0; s < count; s += 4) {
    uint4* g = reinterpret_cast<uint4*>(global + s);
    uint32_t* l = lists + s * 32 + row;
    if (kToGlobal) {
      *g = make_uint4(l[0], l[32], l[64], l[96]);
    } else {
      const uint4 v = *g;
      l[0] = v.x;
      l[32] = v.y;
      l[64] = v.z;
      l[96] = v.w;
    }
  }
}

// Keys that found their list full wait here for the conflict-free pass.
struct FullListKey {
  uint32_t key = 0;
  int row = -1;  // none
};

// One lane per list at a time (lanes holding keys for the same list take
// turns), each replacing in-lane.
__device__ __forceinline__ void ReplaceInFullLists(FullListKey pending, uint32_t* lists, uint32_t* limits,
                                                   int capacity) {
  const unsigned lane = LaneId();
  unsigned active = __ballot_sync(kFullWarpMask, pending.row >= 0);
  while (active != 0) {
    if (pending.row >= 0) {
      const unsigned peers = __match_any_sync(active, pending.row);
      if (static_cast<int>(lane) == __ffs(peers) - 1) {
        if (pending.key < limits[pending.row]) {
          limits[pending.row] = ReplaceLargest(lists, pending.row, capacity, pending.key);
        }
        pending.row = -1;
      }
    }
    __syncwarp();
    active = __ballot_sync(kFullWarpMask, pending.row >= 0);
  }
}

__global__ void __launch_bounds__(kTileThreads) CascadeTileKernel(const PairTask* tasks, uint32_t total_items,
                                                                  MatchParams params, CandidateLists lists) {
  __shared__ TileScratch scratch;
  extern __shared__ uint32_t dynamic_lists[];
  const unsigned lane = LaneId();
  const uint32_t item = blockIdx.x;
  if (item >= total_items) return;

  const int bits = params.bits_per_table;
  const uint32_t buckets = 1u << bits;
  const uint32_t num_tables = static_cast<uint32_t>(params.num_tables);
  const uint32_t per_task = num_tables * buckets;
  const uint32_t task_index = item / per_task;
  const uint32_t t = (item - task_index * per_task) >> bits;
  const uint32_t bucket = item & (buckets - 1);
  const PairTask& task = tasks[task_index];

  const uint32_t* offsets_a = task.a.offsets + t * (buckets + 1) + bucket;
  const uint32_t* offsets_b = task.b.offsets + t * (buckets + 1) + bucket;
  const uint32_t a_begin = offsets_a[0], a_end = offsets_a[1];
  const uint32_t b_begin = offsets_b[0], b_end = offsets_b[1];
  if (a_begin == a_end || b_begin == b_end) return;

  const BucketEntry* entries_a = task.a.entries + size_t(t) * task.a.num_features;
  const BucketEntry* entries_b = task.b.entries + size_t(t) * task.b.num_features;
  const size_t rows_a = task.list_offset;
  const size_t rows_b = size_t(task.list_offset) + task.a.num_features;
  const int capacity = lists.capacity;  // 16 or 32
  uint32_t* lists_a = dynamic_lists;                  // [slot][32 A rows]
  uint32_t* lists_b = dynamic_lists + 32 * capacity;  // [slot][32 staged B entries]
  auto global_list = [&](size_t first_row, uint32_t index) {
    return lists.keys + ((first_row + index) * num_tables + t) * capacity;
  };
  auto global_count = [&](size_t first_row, uint32_t index) {
    return lists.counts + (first_row + index) * num_tables + t;
  };
  const uint32_t tau = static_cast<uint32_t>(min(params.tau, 128));
  // Duplicate test (see EntryKey in cascade_match_kernels.cu): fields of the
  // tables before t must all differ.
  const uint64_t below = (uint64_t{1} << (t * bits)) - 1;
  const uint64_t high_from_t = params.field_high_bits & ~below;

  for (uint32_t a0 = a_begin; a0 < a_end; a0 += 32) {
    const int rows = static_cast<int>(min(32u, a_end - a0));
    const bool a_valid = static_cast<int>(lane) < rows;
    const int row_tau = a_valid ? static_cast<int>(tau) : -1;  // lanes past the rows find nothing
    const uint4* entry_a = reinterpret_cast<const uint4*>(entries_a + min(a0 + lane, a_end - 1));
    const uint4 code_a = __ldg(entry_a);
    const uint4 meta_a = __ldg(entry_a + 1);
    __syncwarp();
    scratch.signature_a[lane] = uint64_t(meta_a.y) << 32 | meta_a.x;
    scratch.index_a[lane] = meta_a.z;
    scratch.seen_a[lane] = 0;
    scratch.limit_a[lane] = kNoLimit;

    for (uint32_t b0 = b_begin; b0 < b_end; b0 += 32) {
      const int chunk = static_cast<int>(min(32u, b_end - b0));
      __syncwarp();
      if (static_cast<int>(lane) < chunk) {
        const uint4* entry_b = reinterpret_cast<const uint4*>(entries_b + b0 + lane);
        const uint4 meta_b = __ldg(entry_b + 1);
        scratch.code[lane] = __ldg(entry_b);
        scratch.signature[lane] = uint64_t(meta_b.y) << 32 | meta_b.x;
        scratch.index[lane] = meta_b.z;
        uint32_t count = 0;
        uint32_t limit = kNoLimit;
        // The first rows of A start every B list of this table empty; later
        // rows continue the lists where the previous rows left them.
        if (a0 != a_begin) {
          count = *global_count(rows_b, meta_b.z);
          CopyList<false>(lists_b, static_cast<int>(lane), count, global_list(rows_b, meta_b.z));
          if (static_cast<int>(count) == capacity) limit = ListMax(lists_b, static_cast<int>(lane), capacity);
        }
        scratch.count[lane] = count;
        scratch.limit_b[lane] = limit;
      }
      __syncwarp();

      // Hot loop: one broadcast load and ~16 instructions per candidate,
      // branch-free (the stripe slot is written every time and kept only
      // when the candidate is within tau).
      int found = 0;
#pragma unroll 4
      for (int j = 0; j < chunk; ++j) {
        const uint4 c = scratch.code[j];
        const int distance = __popc(code_a.x ^ c.x) + __popc(code_a.y ^ c.y) + __popc(code_a.z ^ c.z) +
                             __popc(code_a.w ^ c.w);
        scratch.stripe[found][lane] = static_cast<uint16_t>(j | distance << 8);
        found += distance <= row_tau ? 1 : 0;
      }

      // Survivors are numbered across the lanes (exclusive scan of `found`);
      // lane L of a round takes number q0 + L from the stripe of the last
      // lane whose first number is not above it (a 5-step binary search).
      uint32_t before = static_cast<uint32_t>(found);
#pragma unroll
      for (int d = 1; d < 32; d <<= 1) {
        const uint32_t o = __shfl_up_sync(kFullWarpMask, before, d);
        if (static_cast<int>(lane) >= d) before += o;
      }
      const uint32_t total = __shfl_sync(kFullWarpMask, before, 31);
      before -= static_cast<uint32_t>(found);

      // Append the survivors to both sides' lists, 32 at a time. A key not
      // below its list's limit cannot enter it (limits only decrease).
      for (uint32_t q0 = 0; q0 < total; q0 += 32) {
        FullListKey full_a, full_b;
        int filled_a = -1, filled_b = -1;  // lists this lane just filled
        const uint32_t number = q0 + lane;
        uint32_t row = 0;
#pragma unroll
        for (uint32_t step = 16; step > 0; step >>= 1) {
          if (__shfl_sync(kFullWarpMask, before, row + step) <= number) row += step;
        }
        const uint32_t slot = number - __shfl_sync(kFullWarpMask, before, row);
        if (number < total) {
          const uint32_t e = scratch.stripe[slot][row];
          const uint32_t j = e & 31u, distance = e >> 8;
          const uint64_t v = ((scratch.signature_a[row] ^ scratch.signature[j]) & below) | high_from_t;
          const bool duplicate = ((v - params.field_low_bits) & ~v & params.field_high_bits) != 0;
          if (!duplicate) {
            const uint32_t key_a = distance << 24 | scratch.index[j];
            if (key_a < scratch.limit_a[row]) {
              const int pos = static_cast<int>(atomicAdd(&scratch.seen_a[row], 1u));
              if (pos < capacity) {
                lists_a[pos * 32 + row] = key_a;
                if (pos == capacity - 1) filled_a = static_cast<int>(row);
              } else {
                full_a.key = key_a;
                full_a.row = static_cast<int>(row);
              }
            }
            const uint32_t key_b = distance << 24 | scratch.index_a[row];
            if (key_b < scratch.limit_b[j]) {
              const int pos = static_cast<int>(atomicAdd(&scratch.count[j], 1u));
              if (pos < capacity) {
                lists_b[pos * 32 + j] = key_b;
                if (pos == capacity - 1) filled_b = static_cast<int>(j);
              } else {
                full_b.key = key_b;
                full_b.row = static_cast<int>(j);
              }
            }
          }
        }
        __syncwarp();
        // A list filled in this round gets its limit from the lane that
        // filled it (one per list), before any key is tested against it.
        if (filled_a >= 0) scratch.limit_a[filled_a] = ListMax(lists_a, filled_a, capacity);
        if (filled_b >= 0) scratch.limit_b[filled_b] = ListMax(lists_b, filled_b, capacity);
        __syncwarp();
        ReplaceInFullLists(full_a, lists_a, scratch.limit_a, capacity);
        ReplaceInFullLists(full_b, lists_b, scratch.limit_b, capacity);
      }
      __syncwarp();
      if (static_cast<int>(lane) < chunk) {
        const uint32_t count = min(scratch.count[lane], static_cast<uint32_t>(capacity));
        CopyList<true>(lists_b, static_cast<int>(lane), count, global_list(rows_b, scratch.index[lane]));
        *global_count(rows_b, scratch.index[lane]) = static_cast<uint8_t>(count);
      }
    }
    __syncwarp();
    if (a_valid) {
      const uint32_t count = min(scratch.seen_a[lane], static_cast<uint32_t>(capacity));
      CopyList<true>(lists_a, static_cast<int>(lane), count, global_list(rows_a, scratch.index_a[lane]));
      *global_count(rows_a, scratch.index_a[lane]) = static_cast<uint8_t>(count);
    }
  }
}

}  // namespace

void LaunchCascadeTiles(const PairTask* tasks, int num_tasks, const MatchParams& params, CandidateLists lists,
                        cudaStream_t stream) {
  if (num_tasks == 0) return;
  const uint64_t items = uint64_t(num_tasks) * params.num_tables * (uint64_t{1} << params.bits_per_table);
  const size_t list_bytes = 2 * 32 * size_t(lists.capacity) * sizeof(uint32_t);
  CascadeTileKernel<<<static_cast<unsigned>(items), kTileThreads, list_bytes, stream>>>(
      tasks, static_cast<uint32_t>(items), params, lists);
  CUDA_CHECK_LAUNCH();
}

}  // namespace cuda
}  // namespace cashash
