// Exact matching with COLMAP's brute-force SIFT semantics: for every feature
// the best and second best of the other image by integer dot product (ties:
// lowest index is best), COLMAP's angle ratio / max_distance test
// (descriptor_distance.h), no match when the best dot is 0, and with
// cross_check only mutual best matches.
//
// The dot products are exact integers on every kernel, so every kernel
// gives the same matches; the fastest one the processor runs is chosen at
// run time (one binary for plain x86-64-v3 and for VNNI processors):
//  - kInt8Vnni512: AVX-512 VNNI vpdpbusd, 64 byte products per instruction.
//    vpdpbusd multiplies unsigned by signed bytes, so one side is stored as
//    d - 128 (signed) and the product corrected exactly:
//    a . b = (a - 128) . b + 128 * sum(b).
//  - kInt8AvxVnni: the same with the 256-bit AVX-VNNI instruction.
//  - kInt16Avx2: descriptors widened to int16, vpmaddwd (16 products per
//    instruction), the x86-64-v3 baseline.
// docs/cpu_matching.md counts the work per pair and the machine's peak.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "cashash/matching/matching_options.h"
#include "cashash/base/types.h"

namespace cashash {

enum class DotKernel { kInt16Avx2, kInt8AvxVnni, kInt8Vnni512 };

// Whether this processor (and this build) runs the kernel.
bool DotKernelAvailable(DotKernel kernel);
// The fastest available kernel: kInt8Vnni512, else kInt8AvxVnni, else kInt16Avx2.
DotKernel BestDotKernel();
std::string DotKernelName(DotKernel kernel);

// Descriptors laid out for one kernel.
//  - kInt16Avx2: `data`, rows widened to int16 and padded with zero rows to
//    a multiple of kRowPadding. Zero rows have dot 0 with everything, which
//    never changes a best or second best.
//  - int8 kernels: `signed_rows` (d - 128, rows padded to a multiple of
//    kRowPadding with rows of -128) for the side whose rows are queried,
//    `columns` (the bytes d, in groups of kColumnGroup features: for each
//    4 dimensions the 4 bytes of each of the group's features, the layout
//    vpdpbusd reads) and `column_sums` (128 * sum(d) each, the correction),
//    padded with zero features to a multiple of kColumnPadding. A padding
//    row or column has dot exactly 0 with everything.
struct WideDescriptors {
  static constexpr size_t kRowPadding = 4;
  static constexpr size_t kColumnGroup = 16;
  static constexpr size_t kColumnPadding = 32;
  DotKernel kernel = DotKernel::kInt16Avx2;
  size_t rows = 0;  // real rows, without padding
  std::vector<int16_t> data;
  std::vector<int8_t> signed_rows;
  std::vector<uint8_t> columns;
  std::vector<int32_t> column_sums;

  // kInt16Avx2 layout.
  size_t padded_rows() const { return data.size() / kDescriptorDim; }
  const int16_t* row(size_t i) const { return data.data() + i * kDescriptorDim; }
};

WideDescriptors WidenDescriptors(const FeatureDescriptors& descriptors, size_t num_rows,
                                 DotKernel kernel = BestDotKernel());

// Best and second best dot product of each feature against the other image.
struct BestTwo {
  std::vector<int> best_dot;
  std::vector<int> best_index;  // -1 when every dot was 0
  std::vector<int> second_dot;
};

// One pass over the full dot-product matrix gives both directions. a and b
// must be laid out for the same kernel.
void ComputeBestTwoBothWays(const WideDescriptors& a, const WideDescriptors& b, BestTwo* a_to_b,
                            BestTwo* b_to_a);

// Matches of (a, b) sorted by point2D_idx1.
FeatureMatches BruteForceMatchPair(const WideDescriptors& a, const WideDescriptors& b,
                                   const SiftMatchingOptions& options);

}  // namespace cashash
