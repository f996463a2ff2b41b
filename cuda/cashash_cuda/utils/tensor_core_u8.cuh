// Thin wrappers over the PTX instructions the u8 tensor-core kernels use:
// 16-byte global->shared copies, ldmatrix and the m16n8k32 u8 x u8 -> s32
// matrix multiply-accumulate.
//
// The path is chosen at compile time per architecture (__CUDA_ARCH__):
// - 8.0 and later: cp.async copies and the m16n8k32 u8 mma.
// - 7.5 (T4, RTX 20 series), which has neither: plain 16-byte loads and
//   stores (CopyAsyncCommit / CopyAsyncWait do nothing, so the copy is
//   complete when CopyAsync16 returns and the callers' barriers suffice), and
//   the m16n8k32 product composed of four m8n8k16 u8 mma with the same
//   fragments. Both are exact integer dot products, so every path gives the
//   same sums.
// ldmatrix exists from 7.5 on. Older architectures are not supported (the
// CUDA 13 toolkit does not compile for them).
#pragma once

#include <cstdint>

#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ < 750
#error "cashash's CUDA kernels need compute capability 7.5 or later"
#endif

namespace cashash {
namespace cuda {

__device__ __forceinline__ uint32_t SharedAddress(const void* p) {
  return static_cast<uint32_t>(__cvta_generic_to_shared(p));
}

// The 7.5 copy: a plain 16-byte load and shared store (zeros when !valid).
__device__ __forceinline__ void CopyPlain16(uint32_t dst, const void* src, bool valid) {
  uint4 v = make_uint4(0u, 0u, 0u, 0u);
  if (valid) v = __ldcg(reinterpret_cast<const uint4*>(src));
  asm volatile("st.shared.v4.u32 [%0], {%1, %2, %3, %4};\n" ::"r"(dst), "r"(v.x), "r"(v.y), "r"(v.z), "r"(v.w)
               : "memory");
}

// Copies 16 bytes, or writes 16 zero bytes when !valid (src is not read).
__device__ __forceinline__ void CopyAsync16(uint32_t dst, const void* src, bool valid) {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 800
  const int src_bytes = valid ? 16 : 0;
  asm volatile("cp.async.cg.shared.global [%0], [%1], 16, %2;\n" ::"r"(dst), "l"(src), "r"(src_bytes)
               : "memory");
#else
  CopyPlain16(dst, src, valid);
#endif
}
__device__ __forceinline__ void CopyAsyncCommit() {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 800
  asm volatile("cp.async.commit_group;\n" ::: "memory");
#endif
}
template <int kPending>
__device__ __forceinline__ void CopyAsyncWait() {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 800
  asm volatile("cp.async.wait_group %0;\n" ::"n"(kPending) : "memory");
#endif
}

// Four 8x8 b16 matrices; lanes 8i..8i+7 give the row addresses of matrix i.
__device__ __forceinline__ void LoadMatrixX4(uint32_t address, uint32_t (&r)[4]) {
  asm volatile("ldmatrix.sync.aligned.m8n8.x4.shared.b16 {%0, %1, %2, %3}, [%4];\n"
               : "=r"(r[0]), "=r"(r[1]), "=r"(r[2]), "=r"(r[3])
               : "r"(address)
               : "memory");
}

// d (2 s32: row g, columns 2t and 2t + 1) += a (8x16 u8, row g, bytes
// 4t..4t+3) * b (16x8 u8, column g, bytes 4t..4t+3): the 7.5 instruction.
__device__ __forceinline__ void MmaU8m8n8k16(int& d0, int& d1, uint32_t a, uint32_t b) {
  asm("mma.sync.aligned.m8n8k16.row.col.s32.u8.u8.s32 {%0, %1}, {%2}, {%3}, {%0, %1};\n"
      : "+r"(d0), "+r"(d1)
      : "r"(a), "r"(b));
}

// d += a (16x32 u8, row-major fragment) * b (32x8 u8, column fragment) on
// 7.5: four m8n8k16, which have the same per-lane layout for one 8-row half
// and one 16-byte half of K (rows g and g + 8 are two m8 products, K 32 is
// two k16 steps). Fragments as MmaU8.
__device__ __forceinline__ void MmaU8Sm75(int (&d)[4], const uint32_t (&a)[4], uint32_t b0, uint32_t b1) {
  MmaU8m8n8k16(d[0], d[1], a[0], b0);
  MmaU8m8n8k16(d[0], d[1], a[2], b1);
  MmaU8m8n8k16(d[2], d[3], a[1], b0);
  MmaU8m8n8k16(d[2], d[3], a[3], b1);
}

// d += a (16x32 u8, row-major fragment) * b (32x8 u8, column fragment).
// Fragments (g = lane / 4, t = lane % 4): a[r] holds row g (+8 for r odd),
// bytes 4t..4t+3 (+16 for r >= 2); b0 / b1 column g, bytes 4t..4t+3 / +16;
// d[0..1] row g, d[2..3] row g + 8, columns 2t and 2t + 1.
__device__ __forceinline__ void MmaU8(int (&d)[4], const uint32_t (&a)[4], uint32_t b0, uint32_t b1) {
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 800
  // Not volatile: a pure register operation the compiler may schedule.
  asm(
      "mma.sync.aligned.m16n8k32.row.col.s32.u8.u8.s32 {%0, %1, %2, %3}, {%4, %5, %6, %7}, {%8, %9}, "
      "{%0, %1, %2, %3};\n"
      : "+r"(d[0]), "+r"(d[1]), "+r"(d[2]), "+r"(d[3])
      : "r"(a[0]), "r"(a[1]), "r"(a[2]), "r"(a[3]), "r"(b0), "r"(b1));
#else
  MmaU8Sm75(d, a, b0, b1);
#endif
}

}  // namespace cuda
}  // namespace cashash
