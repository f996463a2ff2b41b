// Kernels of cascade_tile_kernels.cuh.
//
// Cost model (8192 features per image, 8 tables x 7 bits, real SIFT): a
// query meets ~730 bucket entries over the tables, so a pair has ~6M
// (a, b, table) candidate pairs, of which ~6 % are within tau. Each costs one
// broadcast shared load per 32 and ~16 lane instructions (4 XOR, 4 POPC,
// adds, the tau test and a branch-free append), both directions at once:
// ~3M warp instructions per pair. A survivor costs a duplicate test, a
// shared atomic and two stores. History (H100, same benchmark): per-table
// lists of 16 or 32 keys kept in order by replacing the largest key spent
// more than half of the kernel's 14-16M warp instructions per pair on list
// upkeep; append-only lists removed it.
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

// Shared memory of the warp: the staged chunk of B's bucket, per staged
// entry the number of keys it receives in this step and the first list slot
// reserved for them, and the per-lane stripes of survivors (entry = chunk
// position | distance << 5 | rank among the staged entry's keys << 13,
// stored [n][lane] so that the lanes' appends hit distinct banks).
struct TileScratch {
  uint4 code[32];
  uint64_t signature[32];
  uint32_t index[32];
  uint32_t received[32];
  uint32_t base[32];
  uint32_t stripe[33][32];  // one spare row: the branch-free append
};

__global__ void __launch_bounds__(kTileThreads) CascadeTileKernel(const PairTask* tasks, uint32_t total_items,
                                                                  MatchParams params, CandidateLists lists) {
  __shared__ TileScratch scratch;
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
  const uint32_t capacity = static_cast<uint32_t>(lists.capacity);
  const uint32_t tau = static_cast<uint32_t>(min(params.tau, 128));
  // Duplicate test (see EntryKey in cascade_match_kernels.cu): fields of the
  // tables before t must all differ.
  const uint64_t below = (uint64_t{1} << (t * bits)) - 1;
  const uint64_t high_from_t = params.field_high_bits & ~below;

  for (uint32_t a0 = a_begin; a0 < a_end; a0 += 32) {
    const bool a_valid = a0 + lane < a_end;
    const int row_tau = a_valid ? static_cast<int>(tau) : -1;  // lanes past the rows find nothing
    const uint4* entry_a = reinterpret_cast<const uint4*>(entries_a + min(a0 + lane, a_end - 1));
    const uint4 code_a = __ldg(entry_a);
    const uint4 meta_a = __ldg(entry_a + 1);
    const uint64_t signature_a = uint64_t(meta_a.y) << 32 | meta_a.x;
    const uint32_t index_a = meta_a.z;
    const size_t row_a = rows_a + index_a;

    for (uint32_t b0 = b_begin; b0 < b_end; b0 += 32) {
      const int chunk = static_cast<int>(min(32u, b_end - b0));
      __syncwarp();
      if (static_cast<int>(lane) < chunk) {
        const uint4* entry_b = reinterpret_cast<const uint4*>(entries_b + b0 + lane);
        const uint4 meta_b = __ldg(entry_b + 1);
        scratch.code[lane] = __ldg(entry_b);
        scratch.signature[lane] = uint64_t(meta_b.y) << 32 | meta_b.x;
        scratch.index[lane] = meta_b.z;
      }
      scratch.received[lane] = 0;
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
        scratch.stripe[found][lane] = static_cast<uint32_t>(j | distance << 5);
        found += distance <= row_tau ? 1 : 0;
      }

      // Drop duplicates (compacting the stripe in place) and rank each
      // survivor among the keys of its B entry.
      int kept = 0;
      for (int i = 0; i < found; ++i) {
        const uint32_t e = scratch.stripe[i][lane];
        const uint32_t j = e & 31u;
        const uint64_t v = ((signature_a ^ scratch.signature[j]) & below) | high_from_t;
        if (((v - params.field_low_bits) & ~v & params.field_high_bits) == 0) {
          const uint32_t rank = atomicAdd(&scratch.received[j], 1u);
          scratch.stripe[kept++][lane] = e | rank << 13;
        }
      }
      __syncwarp();
      // Reserve list slots: one atomic per A row and per staged B entry.
      const uint32_t base_a = kept > 0 ? atomicAdd(lists.counts + row_a, static_cast<uint32_t>(kept)) : 0u;
      if (static_cast<int>(lane) < chunk && scratch.received[lane] > 0) {
        scratch.base[lane] = atomicAdd(lists.counts + rows_b + scratch.index[lane], scratch.received[lane]);
      }
      __syncwarp();
      for (int i = 0; i < kept; ++i) {
        const uint32_t e = scratch.stripe[i][lane];
        const uint32_t j = e & 31u, distance = (e >> 5) & 0xffu, rank = e >> 13;
        const uint32_t index_b = scratch.index[j];
        if (base_a + i < capacity) lists.keys[row_a * capacity + base_a + i] = distance << 24 | index_b;
        const uint32_t slot_b = scratch.base[j] + rank;
        if (slot_b < capacity) lists.keys[(rows_b + index_b) * capacity + slot_b] = distance << 24 | index_a;
      }
    }
  }
}

}  // namespace

void LaunchCascadeTiles(const PairTask* tasks, int num_tasks, const MatchParams& params, CandidateLists lists,
                        cudaStream_t stream) {
  if (num_tasks == 0) return;
  const uint64_t items = uint64_t(num_tasks) * params.num_tables * (uint64_t{1} << params.bits_per_table);
  CascadeTileKernel<<<static_cast<unsigned>(items), kTileThreads, 0, stream>>>(
      tasks, static_cast<uint32_t>(items), params, lists);
  CUDA_CHECK_LAUNCH();
}

}  // namespace cuda
}  // namespace cashash
