// The int8 brute-force kernels: vpdpbusd multiplies 4 unsigned bytes (b's
// columns) by 4 signed bytes (a's rows, stored as d - 128) and adds them to
// an int32 lane. Each lane holds one column's dot; the columns' 128 * sum(b)
// starts the accumulator, so a lane ends at the exact dot a . b. Built for
// the processors that have the instructions (target attributes), called
// only where ProcessorHas... says so: the rest of the binary stays
// x86-64-v3.
#include <algorithm>
#include <cstring>

#include "cashash/matching/best_two_tracker.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <cpuid.h>
#include <immintrin.h>
#define CASHASH_INT8_KERNELS 1
#endif

namespace cashash {

#ifdef CASHASH_INT8_KERNELS

namespace {

// Rows of a per block: 256 rows (32 KiB as bytes) stay in L1/L2 while all
// of b's columns stream past them from L2.
constexpr size_t kBlockRows = 256;
constexpr size_t kGroupBytes = WideDescriptors::kColumnGroup * kDescriptorDim;

inline int32_t LoadFour(const int8_t* p) {
  int32_t value;
  std::memcpy(&value, p, sizeof(value));
  return value;
}

// Folds 16 dots of row i with columns j..j+15 into the trackers. Most dots
// beat neither the row's nor the columns' second best: two compares skip
// them. The lanes that do are visited in ascending column order; a lane
// left out cannot change anything, since the seconds only grow.
__attribute__((target("avx512f,avx512bw,avx512vnni"))) inline void Fold16(__m512i dots, size_t i, size_t j,
                                                                        BestTwo* rows, BestTwo* cols) {
  const __m512i row_second = _mm512_set1_epi32(rows->second_dot[i]);
  const __m512i col_second = _mm512_loadu_si512(cols->second_dot.data() + j);
  unsigned beats = _mm512_cmpgt_epi32_mask(dots, row_second) | _mm512_cmpgt_epi32_mask(dots, col_second);
  if (beats == 0) return;
  alignas(64) int d[16];
  _mm512_store_si512(d, dots);
  for (; beats != 0; beats &= beats - 1) {
    const int c = __builtin_ctz(beats);
    UpdateBothWays(d[c], i, j + c, rows, cols);
  }
}

__attribute__((target("avx2,avxvnni"))) inline void Fold8(__m256i dots, size_t i, size_t j, BestTwo* rows,
                                                         BestTwo* cols) {
  const __m256i row_second = _mm256_set1_epi32(rows->second_dot[i]);
  const __m256i col_second = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(cols->second_dot.data() + j));
  const __m256i beat = _mm256_or_si256(_mm256_cmpgt_epi32(dots, row_second), _mm256_cmpgt_epi32(dots, col_second));
  unsigned beats = static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(beat)));
  if (beats == 0) return;
  alignas(32) int d[8];
  _mm256_store_si256(reinterpret_cast<__m256i*>(d), dots);
  for (; beats != 0; beats &= beats - 1) {
    const int c = __builtin_ctz(beats);
    UpdateBothWays(d[c], i, j + c, rows, cols);
  }
}

}  // namespace

// 4 rows x 32 columns a step: 8 accumulators, two column loads and four
// row broadcasts per 8 vpdpbusd. For every column the rows arrive in
// ascending order (blocks of a outermost, each walked in order), and for
// every row the columns.
__attribute__((target("avx512f,avx512bw,avx512vnni"))) void BestTwoInt8Vnni512(const WideDescriptors& a,
                                                                             const WideDescriptors& b,
                                                                             BestTwo* a_to_b, BestTwo* b_to_a) {
  const size_t na = a.signed_rows.size() / kDescriptorDim;
  const size_t nb = b.column_sums.size();
  for (size_t i0 = 0; i0 < na; i0 += kBlockRows) {
    const size_t i1 = std::min(na, i0 + kBlockRows);
    for (size_t j = 0; j < nb; j += 32) {
      const uint8_t* g0 = b.columns.data() + j * kDescriptorDim;
      const uint8_t* g1 = g0 + kGroupBytes;
      const __m512i s0 = _mm512_loadu_si512(b.column_sums.data() + j);
      const __m512i s1 = _mm512_loadu_si512(b.column_sums.data() + j + 16);
      for (size_t i = i0; i < i1; i += 4) {
        const int8_t* r = a.signed_rows.data() + i * kDescriptorDim;
        __m512i c00 = s0, c01 = s1, c10 = s0, c11 = s1, c20 = s0, c21 = s1, c30 = s0, c31 = s1;
        for (int k = 0; k < kDescriptorDim / 4; ++k) {
          const __m512i y0 = _mm512_loadu_si512(g0 + 64 * k);
          const __m512i y1 = _mm512_loadu_si512(g1 + 64 * k);
          __m512i x = _mm512_set1_epi32(LoadFour(r + 4 * k));
          c00 = _mm512_dpbusd_epi32(c00, y0, x);
          c01 = _mm512_dpbusd_epi32(c01, y1, x);
          x = _mm512_set1_epi32(LoadFour(r + kDescriptorDim + 4 * k));
          c10 = _mm512_dpbusd_epi32(c10, y0, x);
          c11 = _mm512_dpbusd_epi32(c11, y1, x);
          x = _mm512_set1_epi32(LoadFour(r + 2 * kDescriptorDim + 4 * k));
          c20 = _mm512_dpbusd_epi32(c20, y0, x);
          c21 = _mm512_dpbusd_epi32(c21, y1, x);
          x = _mm512_set1_epi32(LoadFour(r + 3 * kDescriptorDim + 4 * k));
          c30 = _mm512_dpbusd_epi32(c30, y0, x);
          c31 = _mm512_dpbusd_epi32(c31, y1, x);
        }
        Fold16(c00, i, j, a_to_b, b_to_a);
        Fold16(c01, i, j + 16, a_to_b, b_to_a);
        Fold16(c10, i + 1, j, a_to_b, b_to_a);
        Fold16(c11, i + 1, j + 16, a_to_b, b_to_a);
        Fold16(c20, i + 2, j, a_to_b, b_to_a);
        Fold16(c21, i + 2, j + 16, a_to_b, b_to_a);
        Fold16(c30, i + 3, j, a_to_b, b_to_a);
        Fold16(c31, i + 3, j + 16, a_to_b, b_to_a);
      }
    }
  }
}

// The same with 256-bit AVX-VNNI: 4 rows x 16 columns (one group) a step.
__attribute__((target("avx2,avxvnni"))) void BestTwoInt8AvxVnni(const WideDescriptors& a, const WideDescriptors& b,
                                                                 BestTwo* a_to_b, BestTwo* b_to_a) {
  const size_t na = a.signed_rows.size() / kDescriptorDim;
  const size_t nb = b.column_sums.size();
  for (size_t i0 = 0; i0 < na; i0 += kBlockRows) {
    const size_t i1 = std::min(na, i0 + kBlockRows);
    for (size_t j = 0; j < nb; j += 16) {
      const uint8_t* g = b.columns.data() + j * kDescriptorDim;
      const __m256i s0 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(b.column_sums.data() + j));
      const __m256i s1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(b.column_sums.data() + j + 8));
      for (size_t i = i0; i < i1; i += 4) {
        const int8_t* r = a.signed_rows.data() + i * kDescriptorDim;
        __m256i c00 = s0, c01 = s1, c10 = s0, c11 = s1, c20 = s0, c21 = s1, c30 = s0, c31 = s1;
        for (int k = 0; k < kDescriptorDim / 4; ++k) {
          const __m256i y0 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(g + 64 * k));
          const __m256i y1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(g + 64 * k + 32));
          __m256i x = _mm256_set1_epi32(LoadFour(r + 4 * k));
          c00 = _mm256_dpbusd_avx_epi32(c00, y0, x);
          c01 = _mm256_dpbusd_avx_epi32(c01, y1, x);
          x = _mm256_set1_epi32(LoadFour(r + kDescriptorDim + 4 * k));
          c10 = _mm256_dpbusd_avx_epi32(c10, y0, x);
          c11 = _mm256_dpbusd_avx_epi32(c11, y1, x);
          x = _mm256_set1_epi32(LoadFour(r + 2 * kDescriptorDim + 4 * k));
          c20 = _mm256_dpbusd_avx_epi32(c20, y0, x);
          c21 = _mm256_dpbusd_avx_epi32(c21, y1, x);
          x = _mm256_set1_epi32(LoadFour(r + 3 * kDescriptorDim + 4 * k));
          c30 = _mm256_dpbusd_avx_epi32(c30, y0, x);
          c31 = _mm256_dpbusd_avx_epi32(c31, y1, x);
        }
        Fold8(c00, i, j, a_to_b, b_to_a);
        Fold8(c01, i, j + 8, a_to_b, b_to_a);
        Fold8(c10, i + 1, j, a_to_b, b_to_a);
        Fold8(c11, i + 1, j + 8, a_to_b, b_to_a);
        Fold8(c20, i + 2, j, a_to_b, b_to_a);
        Fold8(c21, i + 2, j + 8, a_to_b, b_to_a);
        Fold8(c30, i + 3, j, a_to_b, b_to_a);
        Fold8(c31, i + 3, j + 8, a_to_b, b_to_a);
      }
    }
  }
}

bool ProcessorHasVnni512() {
  return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
         __builtin_cpu_supports("avx512vnni");
}

// AVX-VNNI is CPUID leaf 7, sub-leaf 1, EAX bit 4. Read directly: clang 14's
// __builtin_cpu_supports does not know the name "avxvnni" (gcc 12 does).
bool ProcessorHasAvxVnni() {
  unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
  if (!__builtin_cpu_supports("avx2") || !__get_cpuid_count(7, 1, &eax, &ebx, &ecx, &edx)) return false;
  return (eax >> 4) & 1u;
}

#else

void BestTwoInt8Vnni512(const WideDescriptors&, const WideDescriptors&, BestTwo*, BestTwo*) {}
void BestTwoInt8AvxVnni(const WideDescriptors&, const WideDescriptors&, BestTwo*, BestTwo*) {}
bool ProcessorHasVnni512() { return false; }
bool ProcessorHasAvxVnni() { return false; }

#endif

}  // namespace cashash
