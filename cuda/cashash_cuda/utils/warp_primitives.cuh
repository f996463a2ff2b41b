// Small warp-level building blocks shared by the GPU kernels: reductions,
// lane masks, a warp bitonic sort and a warp-resident sorted top-k list.
#pragma once

#include <cstdint>

namespace cashash {
namespace cuda {

constexpr unsigned kFullWarpMask = 0xffffffffu;

__device__ __forceinline__ unsigned LaneId() { return threadIdx.x & 31u; }

// Maximum of a 64-bit value over the warp (every lane gets the result).
__device__ __forceinline__ uint64_t WarpMaxU64(uint64_t v) {
#pragma unroll
  for (int offset = 16; offset > 0; offset >>= 1) {
    const uint64_t other = __shfl_xor_sync(kFullWarpMask, v, offset);
    v = other > v ? other : v;
  }
  return v;
}

// Whole-warp reductions of 32-bit unsigned values (every lane gets the
// result): one redux.sync instruction from 8.0 on, five xor-shuffles on 7.5
// (the *Shuffle forms, callable on every architecture). Integer min, max,
// or and add are exact either way.
__device__ __forceinline__ unsigned WarpReduceOrShuffle(unsigned v) {
#pragma unroll
  for (int offset = 16; offset > 0; offset >>= 1) v |= __shfl_xor_sync(kFullWarpMask, v, offset);
  return v;
}
__device__ __forceinline__ unsigned WarpReduceMinShuffle(unsigned v) {
#pragma unroll
  for (int offset = 16; offset > 0; offset >>= 1) v = min(v, __shfl_xor_sync(kFullWarpMask, v, offset));
  return v;
}
__device__ __forceinline__ unsigned WarpReduceMaxShuffle(unsigned v) {
#pragma unroll
  for (int offset = 16; offset > 0; offset >>= 1) v = max(v, __shfl_xor_sync(kFullWarpMask, v, offset));
  return v;
}
__device__ __forceinline__ unsigned WarpReduceAddShuffle(unsigned v) {
#pragma unroll
  for (int offset = 16; offset > 0; offset >>= 1) v += __shfl_xor_sync(kFullWarpMask, v, offset);
  return v;
}
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 800
__device__ __forceinline__ unsigned WarpReduceOr(unsigned v) { return __reduce_or_sync(kFullWarpMask, v); }
__device__ __forceinline__ unsigned WarpReduceMin(unsigned v) { return __reduce_min_sync(kFullWarpMask, v); }
__device__ __forceinline__ unsigned WarpReduceMax(unsigned v) { return __reduce_max_sync(kFullWarpMask, v); }
__device__ __forceinline__ unsigned WarpReduceAdd(unsigned v) { return __reduce_add_sync(kFullWarpMask, v); }
#else
__device__ __forceinline__ unsigned WarpReduceOr(unsigned v) { return WarpReduceOrShuffle(v); }
__device__ __forceinline__ unsigned WarpReduceMin(unsigned v) { return WarpReduceMinShuffle(v); }
__device__ __forceinline__ unsigned WarpReduceMax(unsigned v) { return WarpReduceMaxShuffle(v); }
__device__ __forceinline__ unsigned WarpReduceAdd(unsigned v) { return WarpReduceAddShuffle(v); }
#endif

// Sum over aligned groups of `width` lanes (width a power of two <= 32).
template <int kWidth>
__device__ __forceinline__ int GroupSum(int v) {
#pragma unroll
  for (int offset = kWidth / 2; offset > 0; offset >>= 1) v += __shfl_xor_sync(kFullWarpMask, v, offset);
  return v;
}

// A sorted list of up to 32 unique 32-bit keys spread over the warp: lane i
// holds the i-th smallest key, unused lanes hold kEmptyKey. Insertion costs a
// ballot and a shuffle, so a warp can keep the k best candidates of a query
// without shared memory.
struct WarpSortedList {
  static constexpr uint32_t kEmptyKey = 0xffffffffu;
  uint32_t key = kEmptyKey;

  // Inserts `k` (which every lane passes, and which must not be present);
  // the largest key falls off the end of the 32-lane list.
  __device__ __forceinline__ void Insert(uint32_t k) {
    const unsigned lane = LaneId();
    const unsigned smaller = __ballot_sync(kFullWarpMask, key < k);
    const unsigned pos = __popc(smaller);
    const uint32_t up = __shfl_up_sync(kFullWarpMask, key, 1);
    if (lane > pos) key = up;
    else if (lane == pos) key = k;
  }
  // Key at position i (every lane gets it).
  __device__ __forceinline__ uint32_t At(int i) const { return __shfl_sync(kFullWarpMask, key, i); }

  // Merges 32 keys sorted ascending over the lanes (`sorted`, unique and
  // absent from the list, kEmptyKey allowed): keeps the 32 smallest of both.
  // min(list[i], sorted[31 - i]) is a bitonic sequence holding exactly those
  // 32, so five half-cleaner steps sort it: 6 shuffles instead of one
  // insertion per key.
  __device__ __forceinline__ void MergeSorted(uint32_t sorted) {
    const unsigned lane = LaneId();
    const uint32_t reversed = __shfl_sync(kFullWarpMask, sorted, 31 - lane);
    key = min(key, reversed);
#pragma unroll
    for (int j = 16; j > 0; j >>= 1) {
      const uint32_t other = __shfl_xor_sync(kFullWarpMask, key, j);
      key = (lane & j) ? max(key, other) : min(key, other);
    }
  }
};

// Bitmask of the lanes below this one.
__device__ __forceinline__ unsigned LaneMaskLt() {
  unsigned mask;
  asm("mov.u32 %0, %%lanemask_lt;" : "=r"(mask));
  return mask;
}

// Bitmask of this lane and the lanes below it.
__device__ __forceinline__ unsigned LaneMaskLe() {
  unsigned mask;
  asm("mov.u32 %0, %%lanemask_le;" : "=r"(mask));
  return mask;
}

// Sorts one 32-bit value per lane ascending over the warp (bitonic network,
// 15 shuffle steps).
__device__ __forceinline__ uint32_t WarpBitonicSort(uint32_t v) {
  const unsigned lane = LaneId();
#pragma unroll
  for (int k = 2; k <= 32; k <<= 1) {
#pragma unroll
    for (int j = k / 2; j > 0; j >>= 1) {
      const uint32_t other = __shfl_xor_sync(kFullWarpMask, v, j);
      // Upper lane of an ascending run or lower lane of a descending run
      // keeps the larger value.
      const bool take_max = ((lane & j) != 0) != ((lane & k) != 0);
      v = take_max ? max(v, other) : min(v, other);
    }
  }
  return v;
}

}  // namespace cuda
}  // namespace cashash
