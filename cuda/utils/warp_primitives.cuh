// Small warp-level building blocks shared by the GPU kernels: reductions,
// a warp-wide exclusive count and a warp-resident sorted top-k list.
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
};

}  // namespace cuda
}  // namespace cashash
