// Single-bit tensor-core products (sm_80 and later).
//
// mma.m16n8k128 with .and.popc: D[i][j] = C[i][j] + popc(A row i & B col j)
// over 128 bits, for a 16 x 8 tile in one warp instruction. Fragments
// (groupID g = lane / 4, t = lane % 4):
//   a0 = word t of A row g, a1 = word t of A row g + 8 (words: 32-bit parts of the 128 bits)
//   b  = word t of B column g
//   d0, d1 = D[g][2t], D[g][2t + 1]; d2, d3 = D[g + 8][2t], D[g + 8][2t + 1]
// With popcounts of both operands this gives Hamming distances:
// popc(a ^ b) = popc(a) + popc(b) - 2 popc(a & b).
#pragma once

#include <cstdint>

namespace cashash {
namespace cuda {

__device__ __forceinline__ void BitAndPopcMma16x8x128(uint32_t a0, uint32_t a1, uint32_t b, int (&d)[4]) {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 800
  asm volatile(
      "mma.sync.aligned.m16n8k128.row.col.s32.b1.b1.s32.and.popc "
      "{%0, %1, %2, %3}, {%4, %5}, {%6}, {%7, %7, %7, %7};"
      : "=r"(d[0]), "=r"(d[1]), "=r"(d[2]), "=r"(d[3])
      : "r"(a0), "r"(a1), "r"(b), "r"(0));
#else
  // Same result without tensor cores (older architectures): lane (g, w)
  // holds word w of A rows g and g + 8 and of B column g.
  const unsigned lane = threadIdx.x & 31u, g = lane >> 2, t = lane & 3u;
  d[0] = d[1] = d[2] = d[3] = 0;
  for (unsigned w = 0; w < 4; ++w) {
    const uint32_t row0 = __shfl_sync(0xffffffffu, a0, (g << 2) | w);
    const uint32_t row1 = __shfl_sync(0xffffffffu, a1, (g << 2) | w);
    const uint32_t col0 = __shfl_sync(0xffffffffu, b, ((2 * t) << 2) | w);
    const uint32_t col1 = __shfl_sync(0xffffffffu, b, ((2 * t + 1) << 2) | w);
    d[0] += __popc(row0 & col0);
    d[1] += __popc(row0 & col1);
    d[2] += __popc(row1 & col0);
    d[3] += __popc(row1 & col1);
  }
#endif
}

}  // namespace cuda
}  // namespace cashash
