#include "cashash/matching/brute_force_matcher.h"

#include <algorithm>
#include <stdexcept>

#include "cashash/matching/best_two_tracker.h"
#include "cashash/matching/descriptor_distance.h"

#if defined(__AVX2__)
#include <immintrin.h>
#endif

namespace cashash {

bool DotKernelAvailable(DotKernel kernel) {
  switch (kernel) {
    case DotKernel::kInt16Avx2:
      return true;  // the build's baseline (a scalar loop without AVX2)
    case DotKernel::kInt8AvxVnni:
      return ProcessorHasAvxVnni();
    case DotKernel::kInt8Vnni512:
      return ProcessorHasVnni512();
  }
  return false;
}

DotKernel BestDotKernel() {
  static const DotKernel best = [] {
    if (DotKernelAvailable(DotKernel::kInt8Vnni512)) return DotKernel::kInt8Vnni512;
    if (DotKernelAvailable(DotKernel::kInt8AvxVnni)) return DotKernel::kInt8AvxVnni;
    return DotKernel::kInt16Avx2;
  }();
  return best;
}

std::string DotKernelName(DotKernel kernel) {
  switch (kernel) {
    case DotKernel::kInt16Avx2:
      return "int16-avx2";
    case DotKernel::kInt8AvxVnni:
      return "int8-avx-vnni";
    case DotKernel::kInt8Vnni512:
      return "int8-avx512-vnni";
  }
  return "unknown";
}

namespace {

size_t RoundUp(size_t n, size_t multiple) { return (n + multiple - 1) / multiple * multiple; }

void LayOutInt16(const FeatureDescriptors& descriptors, WideDescriptors* wide) {
  wide->data.assign(RoundUp(wide->rows, WideDescriptors::kRowPadding) * kDescriptorDim, 0);
  for (size_t i = 0; i < wide->rows * kDescriptorDim; ++i) wide->data[i] = descriptors.data[i];
}

void LayOutInt8(const FeatureDescriptors& descriptors, WideDescriptors* wide) {
  const size_t rows = wide->rows;
  wide->signed_rows.assign(RoundUp(rows, WideDescriptors::kRowPadding) * kDescriptorDim, static_cast<int8_t>(-128));
  for (size_t i = 0; i < rows * kDescriptorDim; ++i) {
    wide->signed_rows[i] = static_cast<int8_t>(static_cast<int>(descriptors.data[i]) - 128);
  }
  const size_t padded_columns = RoundUp(rows, WideDescriptors::kColumnPadding);
  wide->columns.assign(padded_columns * kDescriptorDim, 0);
  wide->column_sums.assign(padded_columns, 0);
  constexpr size_t kGroup = WideDescriptors::kColumnGroup;
  for (size_t j = 0; j < rows; ++j) {
    const uint8_t* row = descriptors.row(j);
    uint8_t* group = wide->columns.data() + (j / kGroup) * kGroup * kDescriptorDim;
    const size_t lane = j % kGroup;
    int32_t sum = 0;
    for (int d = 0; d < kDescriptorDim; ++d) {
      group[(d / 4) * kGroup * 4 + lane * 4 + d % 4] = row[d];
      sum += row[d];
    }
    wide->column_sums[j] = 128 * sum;
  }
}

}  // namespace

WideDescriptors WidenDescriptors(const FeatureDescriptors& descriptors, size_t num_rows, DotKernel kernel) {
  WideDescriptors wide;
  wide.kernel = kernel;
  wide.rows = std::min(num_rows, descriptors.rows());
  if (kernel == DotKernel::kInt16Avx2) {
    LayOutInt16(descriptors, &wide);
  } else {
    LayOutInt8(descriptors, &wide);
  }
  return wide;
}

namespace {

// Rows of a per block: the block of a (kBlockA x 256 bytes) stays in L2 while
// all of b streams past it.
constexpr size_t kBlockA = 256;

#if defined(__AVX2__)

// 4 int32 lanes: the sums of acc0..acc3.
inline __m128i ReduceFour(__m256i acc0, __m256i acc1, __m256i acc2, __m256i acc3) {
  const __m256i h = _mm256_hadd_epi32(_mm256_hadd_epi32(acc0, acc1), _mm256_hadd_epi32(acc2, acc3));
  return _mm_add_epi32(_mm256_castsi256_si128(h), _mm256_extracti128_si256(h, 1));
}

// Dots of rows a0, a1 with rows b..b+3.
inline void DotTile2x4(const int16_t* a0, const int16_t* a1, const int16_t* b, __m128i* dots0,
                       __m128i* dots1) {
  __m256i c00 = _mm256_setzero_si256(), c01 = c00, c02 = c00, c03 = c00;
  __m256i c10 = c00, c11 = c00, c12 = c00, c13 = c00;
  for (int k = 0; k < kDescriptorDim; k += 16) {
    const __m256i x0 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(a0 + k));
    const __m256i x1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(a1 + k));
    __m256i y = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(b + k));
    c00 = _mm256_add_epi32(c00, _mm256_madd_epi16(x0, y));
    c10 = _mm256_add_epi32(c10, _mm256_madd_epi16(x1, y));
    y = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(b + kDescriptorDim + k));
    c01 = _mm256_add_epi32(c01, _mm256_madd_epi16(x0, y));
    c11 = _mm256_add_epi32(c11, _mm256_madd_epi16(x1, y));
    y = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(b + 2 * kDescriptorDim + k));
    c02 = _mm256_add_epi32(c02, _mm256_madd_epi16(x0, y));
    c12 = _mm256_add_epi32(c12, _mm256_madd_epi16(x1, y));
    y = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(b + 3 * kDescriptorDim + k));
    c03 = _mm256_add_epi32(c03, _mm256_madd_epi16(x0, y));
    c13 = _mm256_add_epi32(c13, _mm256_madd_epi16(x1, y));
  }
  *dots0 = ReduceFour(c00, c01, c02, c03);
  *dots1 = ReduceFour(c10, c11, c12, c13);
}

// Folds the 4 dots of row i with columns j..j+3 into the trackers. Most
// dots beat neither the row's nor the columns' second best: one vector
// compare skips them.
inline void Fold(__m128i dots, int i, int j, BestTwo* rows, BestTwo* cols) {
  const __m128i row_second = _mm_set1_epi32(rows->second_dot[i]);
  const __m128i col_second =
      _mm_loadu_si128(reinterpret_cast<const __m128i*>(cols->second_dot.data() + j));
  const __m128i beats = _mm_or_si128(_mm_cmpgt_epi32(dots, row_second), _mm_cmpgt_epi32(dots, col_second));
  if (_mm_movemask_epi8(beats) == 0) return;
  alignas(16) int d[4];
  _mm_store_si128(reinterpret_cast<__m128i*>(d), dots);
  for (int c = 0; c < 4; ++c) {
    UpdateBothWays(d[c], static_cast<size_t>(i), static_cast<size_t>(j + c), rows, cols);
  }
}

#else

int ScalarDot(const int16_t* a, const int16_t* b) {
  int dot = 0;
  for (int d = 0; d < kDescriptorDim; ++d) dot += int{a[d]} * int{b[d]};
  return dot;
}

#endif  // __AVX2__

}  // namespace

namespace {

void BestTwoInt16(const WideDescriptors& a, const WideDescriptors& b, BestTwo* a_to_b, BestTwo* b_to_a) {
  const size_t na = a.padded_rows();
  const size_t nb = b.padded_rows();
  for (size_t i0 = 0; i0 < na; i0 += kBlockA) {
    const size_t i1 = std::min(na, i0 + kBlockA);
    // For every column the rows arrive in ascending order: blocks of a are
    // outermost and each block is walked in order.
    for (size_t j = 0; j < nb; j += 4) {
#if defined(__AVX2__)
      for (size_t i = i0; i < i1; i += 2) {
        // na is a multiple of kRowPadding, so row i + 1 exists.
        __m128i dots0, dots1;
        DotTile2x4(a.row(i), a.row(i + 1), b.row(j), &dots0, &dots1);
        Fold(dots0, static_cast<int>(i), static_cast<int>(j), a_to_b, b_to_a);
        Fold(dots1, static_cast<int>(i + 1), static_cast<int>(j), a_to_b, b_to_a);
      }
#else
      for (size_t i = i0; i < i1; ++i) {
        for (size_t c = j; c < j + 4; ++c) {
          const int dot = ScalarDot(a.row(i), b.row(c));
          UpdateBothWays(dot, i, c, a_to_b, b_to_a);
        }
      }
#endif
    }
  }
}

}  // namespace

void ComputeBestTwoBothWays(const WideDescriptors& a, const WideDescriptors& b, BestTwo* a_to_b,
                            BestTwo* b_to_a) {
  if (a.kernel != b.kernel) throw std::invalid_argument("ComputeBestTwoBothWays: a and b laid out for two kernels");
  // Trackers sized to the padded rows and columns; padding only ever sees
  // dot 0 and never updates anything, and is cut off at the end.
  if (a.kernel == DotKernel::kInt16Avx2) {
    InitBestTwo(a.padded_rows(), a_to_b);
    InitBestTwo(b.padded_rows(), b_to_a);
    BestTwoInt16(a, b, a_to_b, b_to_a);
  } else {
    InitBestTwo(a.signed_rows.size() / kDescriptorDim, a_to_b);
    InitBestTwo(b.column_sums.size(), b_to_a);
    if (a.kernel == DotKernel::kInt8Vnni512) {
      BestTwoInt8Vnni512(a, b, a_to_b, b_to_a);
    } else {
      BestTwoInt8AvxVnni(a, b, a_to_b, b_to_a);
    }
  }
  for (BestTwo* best : {a_to_b, b_to_a}) {
    const size_t n = best == a_to_b ? a.rows : b.rows;
    best->best_dot.resize(n);
    best->best_index.resize(n);
    best->second_dot.resize(n);
  }
}

FeatureMatches BruteForceMatchPair(const WideDescriptors& a, const WideDescriptors& b,
                                   const SiftMatchingOptions& options) {
  FeatureMatches matches;
  if (a.rows == 0 || b.rows == 0) return matches;
  BestTwo a_to_b, b_to_a;
  ComputeBestTwoBothWays(a, b, &a_to_b, &b_to_a);
  const float max_ratio = static_cast<float>(options.max_ratio);
  const float max_distance = static_cast<float>(options.max_distance);
  auto accepted = [&](const BestTwo& best, size_t i) {
    return best.best_index[i] >= 0 &&
           AcceptSiftMatch(best.best_dot[i], best.second_dot[i], max_ratio, max_distance);
  };
  for (size_t i = 0; i < a.rows; ++i) {
    if (!accepted(a_to_b, i)) continue;
    const int j = a_to_b.best_index[i];
    if (options.cross_check && (!accepted(b_to_a, j) || b_to_a.best_index[j] != static_cast<int>(i))) {
      continue;
    }
    matches.push_back({static_cast<point2D_t>(i), static_cast<point2D_t>(j)});
  }
  return matches;
}

}  // namespace cashash
