// Exact matching with COLMAP's brute-force SIFT semantics: for every feature
// the best and second best of the other image by integer dot product (ties:
// lowest index is best), COLMAP's angle ratio / max_distance test
// (descriptor_distance.h), no match when the best dot is 0, and with
// cross_check only mutual best matches.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "cashash/matching/matching_options.h"
#include "cashash/base/types.h"

namespace cashash {

// Descriptors widened to int16 and padded with zero rows to a multiple of
// kRowPadding, the layout the blocked dot-product kernel reads. Zero rows
// have dot 0 with everything, which never changes a best or second best.
struct WideDescriptors {
  static constexpr size_t kRowPadding = 4;
  size_t rows = 0;  // real rows, without padding
  std::vector<int16_t> data;

  size_t padded_rows() const { return data.size() / kDescriptorDim; }
  const int16_t* row(size_t i) const { return data.data() + i * kDescriptorDim; }
};

WideDescriptors WidenDescriptors(const FeatureDescriptors& descriptors, size_t num_rows);

// Best and second best dot product of each feature against the other image.
struct BestTwo {
  std::vector<int> best_dot;
  std::vector<int> best_index;  // -1 when every dot was 0
  std::vector<int> second_dot;
};

// One pass over the full dot-product matrix gives both directions.
void ComputeBestTwoBothWays(const WideDescriptors& a, const WideDescriptors& b, BestTwo* a_to_b,
                            BestTwo* b_to_a);

// Matches of (a, b) sorted by point2D_idx1.
FeatureMatches BruteForceMatchPair(const WideDescriptors& a, const WideDescriptors& b,
                                   const SiftMatchingOptions& options);

}  // namespace cashash
