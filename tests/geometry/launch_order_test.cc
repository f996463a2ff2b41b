// LargestFirst: the launch order of a batched estimator, largest work first,
// ties in input order (so the same input gives the same launch).
#include "cashash/geometry/launch_order.h"

#include <gtest/gtest.h>

#include <vector>

namespace cashash {
namespace {

TEST(LaunchOrder, LargestFirstAndTiesInTheirOrder) {
  const std::vector<size_t> work = {15, 4000, 120, 4000, 15, 900};
  EXPECT_EQ(LargestFirst(work), (std::vector<size_t>{1, 3, 5, 2, 0, 4}));
}

TEST(LaunchOrder, EveryIndexOnceAndNothingForNothing) {
  EXPECT_TRUE(LargestFirst({}).empty());
  const std::vector<size_t> work = {7, 7, 7};
  EXPECT_EQ(LargestFirst(work), (std::vector<size_t>{0, 1, 2}));
}

}  // namespace
}  // namespace cashash
