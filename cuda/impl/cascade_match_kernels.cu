// Kernels of cascade_match_kernels.cuh.
//
// Per query (one warp): the lanes stream the query's buckets of all tables
// of the target image 32 entries at a time (BucketEntry rows are contiguous:
// two coalesced 16-byte loads per lane, one 32-byte sector), compute the 128-bit Hamming distance
// with popcount, drop it if > tau or not better than the current k-th key,
// drop duplicates (a candidate counts only in the first table where it shares
// the query's bucket: its signature tells which), and insert the survivors
// into a warp-resident sorted list of keys (distance << 24 | feature). The
// k best keys then get exact integer dot products (dp4a, 8 lanes per
// candidate), and best / second best decide with COLMAP's ratio and distance
// rule. Ties follow cascade_hashing.h: keys are unique and ordered by
// (distance, index); dots by (dot descending, index ascending).
#include "impl/cascade_match_kernels.cuh"

#include "utils/cuda_check.cuh"
#include "utils/warp_primitives.cuh"

namespace cashash {
namespace cuda {
namespace {

constexpr int kThreads = 256;
constexpr uint32_t kIndexMask = kMaxGpuFeatures - 1;
constexpr float kDotNormalisation = 1.0f / (512.0f * 512.0f);

__device__ __forceinline__ float DotToAngle(int dot) {
  return acosf(fminf(kDotNormalisation * static_cast<float>(dot), 1.0f));
}

// Same rule as AcceptSiftMatch (descriptor_distance.h).
__device__ __forceinline__ bool Accept(int best_dot, int second_dot, float max_ratio, float max_distance) {
  const float best_angle = DotToAngle(best_dot);
  if (best_angle > max_distance) return false;
  return best_angle < max_ratio * DotToAngle(second_dot);
}

__device__ __forceinline__ int FindTask(const PairTask* tasks, int num_tasks, uint32_t item) {
  int lo = 0, hi = num_tasks - 1;
  while (lo < hi) {
    const int mid = (lo + hi + 1) / 2;
    if (tasks[mid].item_begin <= item) lo = mid;
    else hi = mid - 1;
  }
  return lo;
}

__device__ __forceinline__ uint32_t Dot16(uint4 a, uint4 b) {
  uint32_t s = __dp4a(a.x, b.x, 0u);
  s = __dp4a(a.y, b.y, s);
  s = __dp4a(a.z, b.z, s);
  return __dp4a(a.w, b.w, s);
}

// Per-warp shared scratch: where each table's bucket starts in the query's
// concatenated candidate stream, and the entry index base of each table.
struct WarpTables {
  uint32_t start[kMaxGpuTables + 1];
  uint32_t base[kMaxGpuTables];
};

// Table holding stream position `pos`, searched upwards from `t` (the
// largest t with start[t] <= pos; empty tables are skipped).
__device__ __forceinline__ int TableOf(const WarpTables& tables, int t, uint32_t pos) {
  while (tables.start[t + 1] <= pos) ++t;
  return t;
}

// Accepted best match in `target` of feature q of `query` (signature and
// code passed in, loaded ahead by the caller), or -1 (the same value in every
// lane).
//
// The buckets of all tables form one stream of candidates, cut into chunks
// of 32 (one per lane); the next chunk's entries are loaded before the
// current one is ranked, so that a warp waits for one L2 round trip per
// chunk at most instead of one per bucket plus one per chunk.
__device__ int MatchQuery(const DeviceImageView& query, uint32_t q, uint64_t signature, ulonglong2 code,
                          const DeviceImageView& target, const MatchParams& params, WarpTables& tables) {
  const unsigned lane = LaneId();
  const int num_tables = params.num_tables;
  const int bits = params.bits_per_table;
  const uint32_t buckets = 1u << bits;
  const uint64_t bucket_mask = buckets - 1;
  const uint32_t n = target.num_features;
  const uint32_t tau = static_cast<uint32_t>(params.tau);

  // Lane t < num_tables reads the bucket of table t; a scan places them.
  uint32_t size = 0, begin = 0;
  if (static_cast<int>(lane) < num_tables) {
    const uint32_t bucket = static_cast<uint32_t>((signature >> (lane * bits)) & bucket_mask);
    const uint32_t* offsets = target.offsets + lane * (buckets + 1) + bucket;
    begin = offsets[0];
    size = offsets[1] - begin;
  }
  uint32_t inclusive = size;
#pragma unroll
  for (int d = 1; d < 32; d <<= 1) {
    const uint32_t o = __shfl_up_sync(kFullWarpMask, inclusive, d);
    if (lane >= static_cast<unsigned>(d)) inclusive += o;
  }
  const uint32_t total = __shfl_sync(kFullWarpMask, inclusive, 31);
  const uint32_t stream_start = inclusive - size;
  __syncwarp();
  tables.start[lane] = static_cast<int>(lane) < num_tables ? stream_start : 0xffffffffu;
  tables.base[lane] = lane * n + begin - stream_start;
  if (lane == 0) tables.start[kMaxGpuTables] = 0xffffffffu;
  __syncwarp();

  // Chunk 0.
  uint32_t pos = lane;
  int t = TableOf(tables, 0, pos);
  uint4 c = make_uint4(0, 0, 0, 0), s = make_uint4(0, 0, 0, 0);
  if (pos < total) {
    const uint4* entry = reinterpret_cast<const uint4*>(target.entries + (tables.base[t] + pos));
    c = __ldg(entry);
    s = __ldg(entry + 1);
  }

  WarpSortedList ranked;
  uint32_t kth = WarpSortedList::kEmptyKey;  // key of the k-th ranked candidate
  for (uint32_t first = 0; first < total; first += 32) {
    // Load the next chunk ahead.
    const uint32_t next_pos = first + 32 + lane;
    const int next_t = TableOf(tables, __shfl_sync(kFullWarpMask, t, 31), next_pos);
    uint4 next_c = make_uint4(0, 0, 0, 0), next_s = make_uint4(0, 0, 0, 0);
    if (next_pos < total) {
      const uint4* entry = reinterpret_cast<const uint4*>(target.entries + (tables.base[next_t] + next_pos));
      next_c = __ldg(entry);
      next_s = __ldg(entry + 1);
    }

    uint32_t key = WarpSortedList::kEmptyKey;
    if (pos < total) {
      const uint32_t distance = __popcll(code.x ^ (uint64_t(c.y) << 32 | c.x)) +
                                __popcll(code.y ^ (uint64_t(c.w) << 32 | c.z));
      const uint32_t candidate = (distance << 24) | s.z;
      if (distance <= tau && candidate < kth) {
        // Counted only in the first table where it shares the query's bucket:
        // a duplicate has a zero b-bit field of diff below table t. Fields
        // from t up get their top bit set, then the borrow test finds a zero
        // field exactly (a borrow can only start at a zero field).
        const uint64_t diff = signature ^ (uint64_t(s.y) << 32 | s.x);
        const uint64_t below = t == 0 ? 0 : (uint64_t{1} << (t * bits)) - 1;
        const uint64_t v = (diff & below) | (params.field_high_bits & ~below);
        const bool duplicate = ((v - params.field_low_bits) & ~v & params.field_high_bits) != 0;
        if (!duplicate) key = candidate;
      }
    }
    unsigned pending = __ballot_sync(kFullWarpMask, key != WarpSortedList::kEmptyKey);
    while (pending != 0) {
      const int src = __ffs(pending) - 1;
      pending &= pending - 1;
      const uint32_t k = __shfl_sync(kFullWarpMask, key, src);
      if (k < kth) {
        ranked.Insert(k);
        kth = ranked.At(params.top_k - 1);
      }
    }
    pos = next_pos;
    t = next_t;
    c = next_c;
    s = next_s;
  }

  // Exact dot products of the ranked candidates: 4 at a time, 8 lanes each,
  // two rounds per step with both loads issued first.
  const int count = min(__popc(__ballot_sync(kFullWarpMask, ranked.key != WarpSortedList::kEmptyKey)), params.top_k);
  if (count == 0) return -1;
  const unsigned part = lane & 7, group = lane >> 3;
  const uint4 mine = reinterpret_cast<const uint4*>(query.descriptors + size_t(q) * 128)[part];
  int my_dot = 0;
  for (int first = 0; first < count; first += 8) {
    const int j0 = first + static_cast<int>(group), j1 = j0 + 4;
    const uint32_t key0 = ranked.At(min(j0, 31)), key1 = ranked.At(min(j1, 31));
    uint4 other0 = make_uint4(0, 0, 0, 0), other1 = make_uint4(0, 0, 0, 0);
    if (j0 < count) other0 = reinterpret_cast<const uint4*>(target.descriptors + size_t(key0 & kIndexMask) * 128)[part];
    if (j1 < count) other1 = reinterpret_cast<const uint4*>(target.descriptors + size_t(key1 & kIndexMask) * 128)[part];
    const int dot0 = GroupSum<8>(static_cast<int>(Dot16(mine, other0)));
    const int dot1 = GroupSum<8>(static_cast<int>(Dot16(mine, other1)));
    // Lane L in [first, first + 8) takes the dot of candidate L.
    const int rel = static_cast<int>(lane) - first;
    const int got0 = __shfl_sync(kFullWarpMask, dot0, (rel * 8) & 31);
    const int got1 = __shfl_sync(kFullWarpMask, dot1, ((rel - 4) * 8) & 31);
    if (rel >= 0 && rel < 4) my_dot = got0;
    if (rel >= 4 && rel < 8) my_dot = got1;
  }
  // Order (dot descending, index ascending) as one 64-bit maximum.
  const uint64_t value = static_cast<int>(lane) < count
                             ? (uint64_t(uint32_t(my_dot)) << 32) | (0xffffffffu - (ranked.key & kIndexMask))
                             : 0;
  const uint64_t best = WarpMaxU64(value);
  const uint64_t second = WarpMaxU64(value == best ? 0 : value);
  const int best_dot = static_cast<int>(best >> 32);
  const int second_dot = second != 0 ? static_cast<int>(second >> 32) : 0;
  if (best_dot <= 0) return -1;
  if (!Accept(best_dot, second_dot, params.max_ratio, params.max_distance)) return -1;
  return static_cast<int>(0xffffffffu - static_cast<uint32_t>(best));
}

// Forward pass (kReverse = false): best[i] = match of a's feature i in b.
// Reverse pass: for every i with best[i] = j >= 0, query j of b against a
// and clear best[i] unless the answer is i.
template <bool kReverse>
__global__ void __launch_bounds__(kThreads) CascadeMatchKernel(const PairTask* tasks, int num_tasks,
                                                              uint32_t total_items, MatchParams params,
                                                              int32_t* best) {
  __shared__ WarpTables warp_tables[kThreads / 32];
  WarpTables& tables = warp_tables[threadIdx.x >> 5];
  const unsigned lane = LaneId();
  const uint32_t warps = gridDim.x * (kThreads / 32);
  for (uint32_t item = blockIdx.x * (kThreads / 32) + (threadIdx.x >> 5); item < total_items; item += warps) {
    const PairTask* task = tasks + FindTask(tasks, num_tasks, item);
    const DeviceImageView a = task->a;
    const DeviceImageView b = task->b;
    const uint32_t first = (item - task->item_begin) * kQueriesPerItem;
    const uint32_t last = min(first + kQueriesPerItem, a.num_features);
    int32_t* results = best + task->best_offset;
    if (!kReverse) {
      uint64_t signature = a.signatures[first];
      ulonglong2 code = a.codes[first];
      for (uint32_t i = first; i < last; ++i) {
        // The next query's hashes are loaded while this one is matched.
        const uint32_t next = min(i + 1, last - 1);
        const uint64_t next_signature = a.signatures[next];
        const ulonglong2 next_code = a.codes[next];
        const int match = MatchQuery(a, i, signature, code, b, params, tables);
        if (lane == 0) results[i] = match;
        signature = next_signature;
        code = next_code;
      }
    } else {
      const uint32_t i_lane = first + lane;
      const int forward = (lane < kQueriesPerItem && i_lane < last) ? results[i_lane] : -1;
      unsigned todo = __ballot_sync(kFullWarpMask, forward >= 0);
      while (todo != 0) {
        const int src = __ffs(todo) - 1;
        todo &= todo - 1;
        const uint32_t j = static_cast<uint32_t>(__shfl_sync(kFullWarpMask, forward, src));
        const uint32_t i = first + src;
        const int back = MatchQuery(b, j, b.signatures[j], b.codes[j], a, params, tables);
        if (lane == 0 && back != static_cast<int>(i)) results[i] = -1;
      }
    }
  }
}

constexpr int kCompactThreads = 256;

// One block per task: order-preserving compaction of the kept matches.
__global__ void __launch_bounds__(kCompactThreads) CompactKernel(const PairTask* tasks, const int32_t* best,
                                                                 uint2* out, MatchSegment* segments,
                                                                 uint32_t* cursor) {
  __shared__ uint32_t warp_counts[kCompactThreads / 32];
  __shared__ uint32_t s_begin;
  const PairTask& task = tasks[blockIdx.x];
  const uint32_t n = task.a.num_features;
  const int32_t* results = best + task.best_offset;
  const unsigned lane = LaneId(), warp = threadIdx.x >> 5;

  uint32_t total = 0;
  for (uint32_t base = 0; base < n; base += kCompactThreads) {
    const uint32_t i = base + threadIdx.x;
    total += __syncthreads_count(i < n && results[i] >= 0);
  }
  if (threadIdx.x == 0) {
    s_begin = atomicAdd(cursor, total);
    segments[blockIdx.x] = MatchSegment{s_begin, total};
  }
  __syncthreads();
  uint32_t written = s_begin;
  for (uint32_t base = 0; base < n; base += kCompactThreads) {
    const uint32_t i = base + threadIdx.x;
    const int j = i < n ? results[i] : -1;
    const unsigned keep = __ballot_sync(kFullWarpMask, j >= 0);
    if (lane == 0) warp_counts[warp] = __popc(keep);
    __syncthreads();
    uint32_t before = 0, chunk = 0;
    for (unsigned w = 0; w < kCompactThreads / 32; ++w) {
      before += w < warp ? warp_counts[w] : 0;
      chunk += warp_counts[w];
    }
    if (j >= 0) out[written + before + __popc(keep & ((1u << lane) - 1))] = make_uint2(i, uint32_t(j));
    written += chunk;
    __syncthreads();
  }
}

}  // namespace

int CascadeMatchGridSize(int device) {
  int sms = 0, per_sm = 0;
  CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
  CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&per_sm, CascadeMatchKernel<false>, kThreads, 0));
  return sms * (per_sm > 0 ? per_sm : 1);
}

void LaunchCascadeMatch(const PairTask* tasks, int num_tasks, uint32_t total_items, const MatchParams& params,
                        bool cross_check, int grid_size, int32_t* best, cudaStream_t stream) {
  if (num_tasks == 0 || total_items == 0) return;
  const uint32_t needed = (total_items + kThreads / 32 - 1) / (kThreads / 32);
  const int grid = static_cast<int>(needed < static_cast<uint32_t>(grid_size) ? needed : static_cast<uint32_t>(grid_size));
  CascadeMatchKernel<false><<<grid, kThreads, 0, stream>>>(tasks, num_tasks, total_items, params, best);
  CUDA_CHECK_LAUNCH();
  if (cross_check) {
    CascadeMatchKernel<true><<<grid, kThreads, 0, stream>>>(tasks, num_tasks, total_items, params, best);
    CUDA_CHECK_LAUNCH();
  }
}

void LaunchCompactMatches(const PairTask* tasks, int num_tasks, const int32_t* best, uint2* out,
                          MatchSegment* segments, uint32_t* cursor, cudaStream_t stream) {
  if (num_tasks == 0) return;
  CompactKernel<<<num_tasks, kCompactThreads, 0, stream>>>(tasks, best, out, segments, cursor);
  CUDA_CHECK_LAUNCH();
}

}  // namespace cuda
}  // namespace cashash
