// Kernels of cascade_match_kernels.cuh.
//
// Per query (one warp): for each table, the lanes stream the query's bucket
// of the target image 32 entries at a time (BucketEntry rows are contiguous:
// two coalesced 16-byte loads per lane), compute the 128-bit Hamming distance
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

// Accepted best match in `target` of feature q of `query`, or -1 (the same
// value in every lane).
__device__ int MatchQuery(const DeviceImageView& query, uint32_t q, const DeviceImageView& target,
                          const MatchParams& params) {
  const unsigned lane = LaneId();
  const uint64_t signature = query.signatures[q];
  const ulonglong2 code = query.codes[q];
  const int bits = params.bits_per_table;
  const uint32_t buckets = 1u << bits;
  const uint64_t bucket_mask = buckets - 1;
  const uint32_t n = target.num_features;
  const uint32_t tau = static_cast<uint32_t>(params.tau);

  WarpSortedList ranked;
  uint32_t kth = WarpSortedList::kEmptyKey;  // key of the k-th ranked candidate
  for (int t = 0; t < params.num_tables; ++t) {
    const uint32_t bucket = static_cast<uint32_t>((signature >> (t * bits)) & bucket_mask);
    const uint32_t* offsets = target.offsets + t * (buckets + 1);
    const uint32_t begin = offsets[bucket], end = offsets[bucket + 1];
    const BucketEntry* entries = target.entries + size_t(t) * n;
    for (uint32_t base = begin; base < end; base += 32) {
      const uint32_t i = base + lane;
      uint32_t key = WarpSortedList::kEmptyKey;
      if (i < end) {
        const uint4* entry = reinterpret_cast<const uint4*>(entries + i);
        const uint4 c = __ldg(entry);
        const uint32_t distance = __popcll(code.x ^ (uint64_t(c.y) << 32 | c.x)) +
                                  __popcll(code.y ^ (uint64_t(c.w) << 32 | c.z));
        if (distance <= tau) {
          const uint4 s = __ldg(entry + 1);
          const uint32_t candidate = (distance << 24) | s.z;
          if (candidate < kth) {
            const uint64_t diff = signature ^ (uint64_t(s.y) << 32 | s.x);
            bool duplicate = false;
            for (int earlier = 0; earlier < t; ++earlier) {
              duplicate |= ((diff >> (earlier * bits)) & bucket_mask) == 0;
            }
            if (!duplicate) key = candidate;
          }
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
    }
  }

  // Exact dot products of the ranked candidates: 4 at a time, 8 lanes each.
  const int count = min(__popc(__ballot_sync(kFullWarpMask, ranked.key != WarpSortedList::kEmptyKey)), params.top_k);
  if (count == 0) return -1;
  const unsigned part = lane & 7, group = lane >> 3;
  const uint4 mine = reinterpret_cast<const uint4*>(query.descriptors + size_t(q) * 128)[part];
  int my_dot = 0;
  for (int first = 0; first < count; first += 4) {
    const int j = first + static_cast<int>(group);
    const uint32_t key = ranked.At(min(j, 31));
    int dot = 0;
    if (j < count) {
      const uint4 other = reinterpret_cast<const uint4*>(target.descriptors + size_t(key & kIndexMask) * 128)[part];
      dot = static_cast<int>(Dot16(mine, other));
    }
    dot = GroupSum<8>(dot);
    const int from = (static_cast<int>(lane) - first) * 8;
    const int got = __shfl_sync(kFullWarpMask, dot, from & 31);
    if (static_cast<int>(lane) >= first && static_cast<int>(lane) < first + 4) my_dot = got;
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
      for (uint32_t i = first; i < last; ++i) {
        const int match = MatchQuery(a, i, b, params);
        if (lane == 0) results[i] = match;
      }
    } else {
      const uint32_t i_lane = first + lane;
      const int forward = (lane < kQueriesPerItem && i_lane < last) ? results[i_lane] : -1;
      unsigned todo = __ballot_sync(kFullWarpMask, forward >= 0);
      while (todo != 0) {
        const int src = __ffs(todo) - 1;
        todo &= todo - 1;
        const int j = __shfl_sync(kFullWarpMask, forward, src);
        const uint32_t i = first + src;
        const int back = MatchQuery(b, static_cast<uint32_t>(j), a, params);
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
