// Best-two selection primitives: running best and second best of a stream
// of integer scores, with the index of the best, and their merge across the
// lanes of a warp. Ties on the best go to the lower index, and the second
// best is taken over the multiset (two equal best scores make the second
// equal to the best), as COLMAP's brute-force loop does.
#pragma once

namespace cashash {
namespace cuda {

// Hot-loop form: score and position packed into one int key, so a new
// candidate costs three min/max instructions. key = score * 256 + (255 - pos)
// with 0 <= pos < 256 and |score| < 2^23, so the key fits an int, orders by
// score first and, on equal scores, prefers the lower position. The score may
// be relative (a dot less a constant of the row, as BestTwoKernel's are), so
// keys may be negative and "nothing seen" is INT_MIN.
struct PackedBestTwo {
  static constexpr int kPositions = 256;
  static constexpr int kNothing = -2147483647 - 1;  // INT_MIN
  int best = kNothing;    // key
  int second = kNothing;  // key of the second best

  __device__ __forceinline__ void Push(int key) {
    second = max(second, min(best, key));
    best = max(best, key);
  }
  __device__ __forceinline__ void Reset() { best = second = kNothing; }
  __device__ __forceinline__ bool Empty() const { return best == kNothing; }
  // Decoded parts (valid after at least two pushes, resp. one for best); the
  // shift is arithmetic, so a negative score decodes too.
  __device__ __forceinline__ int BestScore() const { return best >> 8; }
  __device__ __forceinline__ int BestPosition() const { return 255 - (best & 255); }
  __device__ __forceinline__ int SecondScore() const { return second >> 8; }
};

// Full form: scores with an explicit index, for merging partial results.
struct IndexedBestTwo {
  int best = -1;    // -1 = nothing seen (scores are >= 0)
  int index = -1;
  int second = 0;   // COLMAP's default second best

  // Merges the best two of another, disjoint set of candidates.
  __device__ __forceinline__ void Merge(int o_best, int o_index, int o_second) {
    const int low = min(best, o_best);
    second = max(low, max(second, o_second));
    if (o_best > best || (o_best == best && o_index < index)) {
      best = o_best;
      index = o_index;
    }
  }
  // Merge over aligned groups of kWidth lanes (every lane gets the result).
  template <int kWidth>
  __device__ __forceinline__ void WarpGroupMerge() {
#pragma unroll
    for (int offset = 1; offset < kWidth; offset <<= 1) {
      const int o_best = __shfl_xor_sync(0xffffffffu, best, offset);
      const int o_index = __shfl_xor_sync(0xffffffffu, index, offset);
      const int o_second = __shfl_xor_sync(0xffffffffu, second, offset);
      Merge(o_best, o_index, o_second);
    }
  }
};

}  // namespace cuda
}  // namespace cashash
