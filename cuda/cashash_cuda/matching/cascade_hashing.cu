// Kernels of LaunchHashAndBucket. Hashing is a (features x 128) by
// (128 x rows) product of integers (projection entries in [-255, 255],
// descriptors in [0, 255]): |partial sums| < 2^24, so fp32 FMAs are exact and
// the bits equal the CPU backend's integer bits. It runs once per image, not
// per pair, so a plain tiled FFMA kernel is far from the bottleneck.
#include "cashash_cuda/matching/cascade_hashing.cuh"

#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/warp_primitives.cuh"

namespace cashash {
namespace cuda {
namespace {

constexpr int kThreads = 256;
constexpr int kWarps = kThreads / 32;
constexpr int kMaxRowGroups = (kMaxSignatureBits + 128) / 32;  // 6
constexpr int kBitWords = kMaxRowGroups + 2;  // two zero words for extraction

__device__ int FindJob(const HashJob* jobs, int num_jobs, uint32_t block) {
  int lo = 0, hi = num_jobs - 1;
  while (lo < hi) {
    const int mid = (lo + hi + 1) / 2;
    if (jobs[mid].block_begin <= block) lo = mid;
    else hi = mid - 1;
  }
  return lo;
}

// 64 bits of the row-bit stream starting at bit `start`.
__device__ __forceinline__ uint64_t ExtractBits(const uint32_t* words, int start) {
  const int w = start >> 5, s = start & 31;
  const uint64_t low = words[w] | (static_cast<uint64_t>(words[w + 1]) << 32);
  const uint64_t high = words[w + 2];
  return (low >> s) | (s != 0 ? high << (64 - s) : 0);
}

__global__ void __launch_bounds__(kThreads) HashKernel(const HashJob* jobs, int num_jobs, HashParams params) {
  __shared__ float4 x[kHashFeaturesPerBlock][32];  // the descriptor as 128 floats
  __shared__ uint32_t bits[kHashFeaturesPerBlock][kBitWords];

  const HashJob& job = jobs[FindJob(jobs, num_jobs, blockIdx.x)];
  const uint32_t first = (blockIdx.x - job.block_begin) * kHashFeaturesPerBlock;
  const uint32_t n = job.parts.num_features;
  const int count = min(static_cast<int>(n - first), kHashFeaturesPerBlock);

  // Stage x: thread handles 4 consecutive dimensions of one feature.
  for (int i = threadIdx.x; i < kHashFeaturesPerBlock * 32; i += kThreads) {
    const int f = i / 32, q = i % 32;
    float4 v = make_float4(0.f, 0.f, 0.f, 0.f);
    if (f < count) {
      const uchar4 d = reinterpret_cast<const uchar4*>(job.parts.descriptors + size_t(first + f) * 128)[q];
      v = make_float4(float(d.x), float(d.y), float(d.z), float(d.w));
    }
    x[f][q] = v;
  }
  for (int i = threadIdx.x; i < kHashFeaturesPerBlock * kBitWords; i += kThreads) (&bits[0][0])[i] = 0;
  __syncthreads();

  // Warp w computes row groups w, w + 8, ...: lane = row within the group,
  // 32 accumulators = the block's 32 features.
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
  const int groups = params.rows_padded / 32;
  for (int g = warp; g < groups; g += kWarps) {
    const int row = g * 32 + lane;
    float acc[kHashFeaturesPerBlock];
#pragma unroll
    for (int f = 0; f < kHashFeaturesPerBlock; ++f) acc[f] = 0.f;
    for (int q = 0; q < 32; ++q) {
      const float p0 = __ldg(params.projections_t + (4 * q + 0) * params.rows_padded + row);
      const float p1 = __ldg(params.projections_t + (4 * q + 1) * params.rows_padded + row);
      const float p2 = __ldg(params.projections_t + (4 * q + 2) * params.rows_padded + row);
      const float p3 = __ldg(params.projections_t + (4 * q + 3) * params.rows_padded + row);
#pragma unroll
      for (int f = 0; f < kHashFeaturesPerBlock; ++f) {
        const float4 v = x[f][q];
        acc[f] = fmaf(p0, v.x, acc[f]);
        acc[f] = fmaf(p1, v.y, acc[f]);
        acc[f] = fmaf(p2, v.z, acc[f]);
        acc[f] = fmaf(p3, v.w, acc[f]);
      }
    }
    const float offset = params.row_offsets[row];
    uint32_t mine = 0;
#pragma unroll
    for (int f = 0; f < kHashFeaturesPerBlock; ++f) {
      const uint32_t word = __ballot_sync(kFullWarpMask, acc[f] > offset);
      if (lane == f) mine = word;
    }
    bits[lane][g] = mine;
  }
  __syncthreads();

  // One thread per feature: cut the bit stream into signature and code, and
  // count the feature into its bucket of every table.
  if (threadIdx.x < count) {
    const int f = threadIdx.x;
    const int sig_bits = params.num_tables * params.bits_per_table;
    uint64_t signature = ExtractBits(bits[f], 0);
    if (sig_bits < 64) signature &= (uint64_t{1} << sig_bits) - 1;
    const ulonglong2 code = make_ulonglong2(ExtractBits(bits[f], sig_bits), ExtractBits(bits[f], sig_bits + 64));
    job.parts.signatures[first + f] = signature;
    job.parts.codes[first + f] = code;
    const uint32_t buckets = 1u << params.bits_per_table;
    const uint64_t mask = buckets - 1;
    for (int t = 0; t < params.num_tables; ++t) {
      const uint32_t bucket = static_cast<uint32_t>((signature >> (t * params.bits_per_table)) & mask);
      atomicAdd(job.parts.offsets + t * (buckets + 1) + bucket, 1u);
    }
  }
}

// Exclusive scan of one table's bucket counts (in place) into CSR offsets,
// copied to the scatter cursors. grid = (jobs, tables).
__global__ void __launch_bounds__(1024) ScanKernel(const HashJob* jobs, HashParams params) {
  __shared__ uint32_t warp_totals[32];
  __shared__ uint32_t carry;
  const HashJob& job = jobs[blockIdx.x];
  const int t = blockIdx.y;
  const uint32_t buckets = 1u << params.bits_per_table;
  uint32_t* offsets = job.parts.offsets + t * (buckets + 1);
  uint32_t* cursors = job.parts.cursors + t * buckets;
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
  if (threadIdx.x == 0) carry = 0;
  __syncthreads();
  for (uint32_t base = 0; base < buckets + 1; base += blockDim.x) {
    const uint32_t i = base + threadIdx.x;
    const uint32_t v = i < buckets + 1 ? offsets[i] : 0;
    uint32_t inclusive = v;
#pragma unroll
    for (int d = 1; d < 32; d <<= 1) {
      const uint32_t o = __shfl_up_sync(kFullWarpMask, inclusive, d);
      if (lane >= d) inclusive += o;
    }
    if (lane == 31) warp_totals[warp] = inclusive;
    __syncthreads();
    if (warp == 0) {
      uint32_t w = lane < static_cast<int>(blockDim.x / 32) ? warp_totals[lane] : 0;
#pragma unroll
      for (int d = 1; d < 32; d <<= 1) {
        const uint32_t o = __shfl_up_sync(kFullWarpMask, w, d);
        if (lane >= d) w += o;
      }
      warp_totals[lane] = w;  // inclusive over warps
    }
    __syncthreads();
    const uint32_t exclusive = carry + (warp > 0 ? warp_totals[warp - 1] : 0) + inclusive - v;
    if (i < buckets + 1) {
      offsets[i] = exclusive;
      if (i < buckets) cursors[i] = exclusive;
    }
    __syncthreads();
    if (threadIdx.x == 0) carry += warp_totals[blockDim.x / 32 - 1];
    __syncthreads();
  }
}

// Places every feature in its bucket of every table (order inside a bucket
// is arbitrary: the matcher's ordering never depends on it).
__global__ void __launch_bounds__(kThreads) ScatterKernel(const HashJob* jobs, int num_jobs, HashParams params) {
  const HashJob& job = jobs[FindJob(jobs, num_jobs, blockIdx.x)];
  const uint32_t first = (blockIdx.x - job.block_begin) * kHashFeaturesPerBlock;
  const uint32_t n = job.parts.num_features;
  const uint32_t f = first + (threadIdx.x % kHashFeaturesPerBlock);
  if (f >= n) return;
  const uint32_t buckets = 1u << params.bits_per_table;
  const uint64_t mask = buckets - 1;
  const uint64_t signature = job.parts.signatures[f];
  const ulonglong2 code = job.parts.codes[f];
  for (int t = threadIdx.x / kHashFeaturesPerBlock; t < params.num_tables; t += kThreads / kHashFeaturesPerBlock) {
    const uint32_t bucket = static_cast<uint32_t>((signature >> (t * params.bits_per_table)) & mask);
    const uint32_t pos = atomicAdd(job.parts.cursors + t * buckets + bucket, 1u);
    BucketEntry e;
    e.code_lo = code.x;
    e.code_hi = code.y;
    e.signature = signature;
    e.index = f;
    e.table_shift = static_cast<uint32_t>(t * params.bits_per_table);
    job.parts.entries[size_t(t) * n + pos] = e;
  }
}

}  // namespace

void LaunchHashAndBucket(const HashJob* jobs, int num_jobs, uint32_t total_blocks, const HashParams& params,
                         cudaStream_t stream) {
  if (num_jobs == 0 || total_blocks == 0) return;
  HashKernel<<<total_blocks, kThreads, 0, stream>>>(jobs, num_jobs, params);
  CUDA_CHECK_LAUNCH();
  ScanKernel<<<dim3(num_jobs, params.num_tables), 1024, 0, stream>>>(jobs, params);
  CUDA_CHECK_LAUNCH();
  ScatterKernel<<<total_blocks, kThreads, 0, stream>>>(jobs, num_jobs, params);
  CUDA_CHECK_LAUNCH();
}

}  // namespace cuda
}  // namespace cashash
