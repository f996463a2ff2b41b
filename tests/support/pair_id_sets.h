// Pairs compared as sets of COLMAP pair ids, so that a test of a pair
// generator states which pairs it expects without caring about their order
// or orientation.
#pragma once

#include <initializer_list>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "cashash/base/pair_id.h"
#include "cashash/base/types.h"

namespace cashash {
namespace testing_support {

// The pair ids of `pairs`; a pair of an image with itself, or a pair given
// twice (in either order), fails the calling test.
inline std::set<pair_t> PairIds(const std::vector<ImagePair>& pairs) {
  std::set<pair_t> ids;
  for (const ImagePair& pair : pairs) {
    EXPECT_NE(pair.first, pair.second);
    EXPECT_TRUE(ids.insert(ImagePairToPairId(pair.first, pair.second)).second) << "pair given twice";
  }
  return ids;
}

inline std::set<pair_t> PairIds(std::initializer_list<ImagePair> pairs) {
  return PairIds(std::vector<ImagePair>(pairs));
}

// The pairs of images 1..n at most `steps` apart.
inline std::set<pair_t> WithinSteps(int n, int steps) {
  std::set<pair_t> ids;
  for (int i = 1; i <= n; ++i) {
    for (int j = i + 1; j <= n && j - i <= steps; ++j) {
      ids.insert(ImagePairToPairId(static_cast<image_t>(i), static_cast<image_t>(j)));
    }
  }
  return ids;
}

}  // namespace testing_support
}  // namespace cashash
