// The blocked brute-force matcher against a naive transcription of COLMAP's
// brute-force semantics.
#include "cashash/matching/brute_force_matcher.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "cashash/matching/descriptor_distance.h"
#include "synthetic_sift.h"

namespace cashash {
namespace {

using testing_support::RandomSift;

std::vector<uint8_t> Perturb(const std::vector<uint8_t>& desc, int amplitude, std::mt19937* rng) {
  std::uniform_int_distribution<int> noise(-amplitude, amplitude);
  std::vector<uint8_t> out(desc);
  for (uint8_t& x : out) x = static_cast<uint8_t>(std::clamp(int(x) + noise(*rng), 0, 255));
  return out;
}

// Image b holds noisy copies of part of a (shuffled) plus unrelated features;
// some features of a get two copies in b and some a near twin in a itself,
// so that ratio test, distance test and cross check all have work to do.
void MakePair(size_t na, size_t nb, int amplitude, uint32_t seed, FeatureDescriptors* a,
              FeatureDescriptors* b) {
  std::mt19937 rng(seed);
  a->data.clear();
  b->data.clear();
  std::vector<std::vector<uint8_t>> rows_a;
  for (size_t i = 0; i < na; ++i) rows_a.push_back(RandomSift(&rng));
  std::vector<std::vector<uint8_t>> rows_b;
  for (size_t i = 0; i < nb; ++i) {
    const bool copy = i < na && i % 3 != 2;
    rows_b.push_back(copy ? Perturb(rows_a[i], amplitude, &rng) : RandomSift(&rng));
    if (copy && i % 5 == 0 && rows_b.size() < nb) rows_b.push_back(Perturb(rows_a[i], amplitude, &rng));
  }
  rows_b.resize(std::min(rows_b.size(), nb));
  for (size_t i = 0; i < na; i += 7) rows_a[na - 1 - i] = Perturb(rows_a[i], amplitude, &rng);
  std::shuffle(rows_b.begin(), rows_b.end(), rng);
  for (const auto& r : rows_a) a->data.insert(a->data.end(), r.begin(), r.end());
  for (const auto& r : rows_b) b->data.insert(b->data.end(), r.begin(), r.end());
}

int NaiveDot(const FeatureDescriptors& a, size_t i, const FeatureDescriptors& b, size_t j) {
  int dot = 0;
  for (int d = 0; d < kDescriptorDim; ++d) dot += int(a.row(i)[d]) * int(b.row(j)[d]);
  return dot;
}

// COLMAP's loop: ascending index, strictly larger dot replaces the best.
std::vector<int> NaiveOneWay(const FeatureDescriptors& a, const FeatureDescriptors& b,
                             const SiftMatchingOptions& o) {
  std::vector<int> result(a.rows(), -1);
  for (size_t i = 0; i < a.rows(); ++i) {
    int best = 0, second = 0, best_j = -1;
    for (size_t j = 0; j < b.rows(); ++j) {
      const int dot = NaiveDot(a, i, b, j);
      if (dot > best) {
        second = best;
        best = dot;
        best_j = int(j);
      } else if (dot > second) {
        second = dot;
      }
    }
    if (best_j < 0) continue;
    const float best_angle = std::acos(std::min(best * kSiftDotNormalisation, 1.0f));
    if (best_angle > float(o.max_distance)) continue;
    const float second_angle = std::acos(std::min(second * kSiftDotNormalisation, 1.0f));
    if (best_angle >= float(o.max_ratio) * second_angle) continue;
    result[i] = best_j;
  }
  return result;
}

FeatureMatches NaiveMatch(const FeatureDescriptors& a, const FeatureDescriptors& b,
                          const SiftMatchingOptions& o) {
  const std::vector<int> ab = NaiveOneWay(a, b, o);
  std::vector<int> ba;
  if (o.cross_check) ba = NaiveOneWay(b, a, o);
  FeatureMatches matches;
  for (size_t i = 0; i < ab.size(); ++i) {
    if (ab[i] < 0) continue;
    if (o.cross_check && ba[ab[i]] != int(i)) continue;
    matches.push_back({point2D_t(i), point2D_t(ab[i])});
  }
  return matches;
}

FeatureMatches Match(const FeatureDescriptors& a, const FeatureDescriptors& b, const SiftMatchingOptions& o,
                     DotKernel kernel = BestDotKernel()) {
  return BruteForceMatchPair(WidenDescriptors(a, a.rows(), kernel), WidenDescriptors(b, b.rows(), kernel), o);
}

const DotKernel kAllKernels[] = {DotKernel::kInt16Avx2, DotKernel::kInt8AvxVnni, DotKernel::kInt8Vnni512};

struct Toggle {
  double max_ratio;
  double max_distance;
  bool cross_check;
};

class BruteForceAgainstNaive : public ::testing::TestWithParam<Toggle> {};

TEST_P(BruteForceAgainstNaive, SameMatches) {
  SiftMatchingOptions o;
  o.max_ratio = GetParam().max_ratio;
  o.max_distance = GetParam().max_distance;
  o.cross_check = GetParam().cross_check;
  // Odd sizes exercise the padding of the 2 x 4 tiles and the 256-row blocks.
  const std::vector<std::pair<size_t, size_t>> sizes = {{37, 53}, {300, 261}, {513, 400}, {1, 7}};
  for (size_t s = 0; s < sizes.size(); ++s) {
    FeatureDescriptors a, b;
    MakePair(sizes[s].first, sizes[s].second, 12, uint32_t(100 + s), &a, &b);
    const FeatureMatches expected = NaiveMatch(a, b, o);
    // Every kernel this processor runs gives the same, exact matches.
    for (const DotKernel kernel : kAllKernels) {
      if (!DotKernelAvailable(kernel)) continue;
      EXPECT_EQ(Match(a, b, o, kernel), expected)
          << DotKernelName(kernel) << ", sizes " << sizes[s].first << " x " << sizes[s].second;
    }
    if (s == 1) {
      EXPECT_GT(expected.size(), 50u);  // the test data does produce matches
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Toggles, BruteForceAgainstNaive,
                         ::testing::Values(Toggle{0.8, 0.7, true}, Toggle{0.8, 0.7, false},
                                           Toggle{1.0, 0.7, true}, Toggle{0.8, 3.0, true},
                                           Toggle{1.0, 3.0, false}, Toggle{0.6, 0.3, true}));

TEST(BruteForce, TogglesChangeTheResult) {
  FeatureDescriptors a, b;
  MakePair(300, 300, 25, 7, &a, &b);
  SiftMatchingOptions strict;
  SiftMatchingOptions no_cross = strict;
  no_cross.cross_check = false;
  SiftMatchingOptions no_ratio = strict;
  no_ratio.max_ratio = 1.0;
  SiftMatchingOptions far = strict;
  far.max_distance = 3.0;
  const size_t base = Match(a, b, strict).size();
  EXPECT_GT(base, 0u);
  EXPECT_GT(Match(a, b, no_cross).size(), base);
  EXPECT_GT(Match(a, b, no_ratio).size(), base);
  EXPECT_GE(Match(a, b, far).size(), base);
}

TEST(BruteForce, TiesGoToTheLowestIndexAndFailTheRatioTest) {
  std::mt19937 rng(3);
  const std::vector<uint8_t> d = RandomSift(&rng);
  FeatureDescriptors a, b;
  a.data = d;
  b.data = RandomSift(&rng);
  b.data.insert(b.data.end(), d.begin(), d.end());
  b.data.insert(b.data.end(), d.begin(), d.end());  // rows 1 and 2 are identical
  SiftMatchingOptions o;
  o.cross_check = false;
  EXPECT_TRUE(Match(a, b, o).empty());  // best == second best: ratio test fails
  for (const DotKernel kernel : kAllKernels) {
    if (!DotKernelAvailable(kernel)) continue;
    BestTwo ab, ba;
    ComputeBestTwoBothWays(WidenDescriptors(a, 1, kernel), WidenDescriptors(b, 3, kernel), &ab, &ba);
    ASSERT_EQ(ab.best_index.size(), 1u) << DotKernelName(kernel);
    EXPECT_EQ(ab.best_index[0], 1) << DotKernelName(kernel);
    EXPECT_EQ(ab.best_dot[0], ab.second_dot[0]) << DotKernelName(kernel);
    ASSERT_EQ(ba.best_index.size(), 3u) << DotKernelName(kernel);
    EXPECT_EQ(ba.best_index[1], 0) << DotKernelName(kernel);
    EXPECT_EQ(ba.second_dot[1], 0) << DotKernelName(kernel);  // one feature in a: second best defaults to 0
  }
  EXPECT_EQ(NaiveMatch(a, b, o), Match(a, b, o));
}

TEST(BruteForce, EmptyAndSingleFeatureImages) {
  std::mt19937 rng(4);
  FeatureDescriptors empty, one, many;
  one.data = RandomSift(&rng);
  for (int i = 0; i < 5; ++i) {
    const auto r = RandomSift(&rng);
    many.data.insert(many.data.end(), r.begin(), r.end());
  }
  many.data.insert(many.data.end(), one.data.begin(), one.data.end());  // exact copy at row 5
  const SiftMatchingOptions o;
  EXPECT_TRUE(Match(empty, many, o).empty());
  EXPECT_TRUE(Match(many, empty, o).empty());
  EXPECT_TRUE(Match(empty, empty, o).empty());
  const FeatureMatches m = Match(one, many, o);
  ASSERT_EQ(m.size(), 1u);
  EXPECT_EQ(m[0], (FeatureMatch{0, 5}));
  EXPECT_EQ(Match(many, one, o), (FeatureMatches{{5, 0}}));
  EXPECT_EQ(Match(one, one, o), (FeatureMatches{{0, 0}}));
}

TEST(BruteForce, AllZeroDescriptorsNeverMatch) {
  // COLMAP keeps no best candidate when every dot is 0, whatever the options.
  FeatureDescriptors a, b;
  a.data.assign(3 * kDescriptorDim, 0);
  b.data.assign(2 * kDescriptorDim, 0);
  SiftMatchingOptions o;
  o.max_ratio = 2.0;
  o.max_distance = 4.0;
  o.cross_check = false;
  EXPECT_TRUE(Match(a, b, o).empty());
}

TEST(BruteForce, WidenTruncatesAndPads) {
  std::mt19937 rng(5);
  FeatureDescriptors a;
  for (int i = 0; i < 6; ++i) {
    const auto r = RandomSift(&rng);
    a.data.insert(a.data.end(), r.begin(), r.end());
  }
  const WideDescriptors w = WidenDescriptors(a, 5, DotKernel::kInt16Avx2);
  EXPECT_EQ(w.rows, 5u);
  EXPECT_EQ(w.padded_rows(), 8u);
  for (int d = 0; d < kDescriptorDim; ++d) {
    EXPECT_EQ(w.row(4)[d], a.row(4)[d]);
    EXPECT_EQ(w.row(5)[d], 0);
  }
}

// The int8 layout: rows as d - 128 padded with -128 rows, columns in groups
// of 16 features, 4 bytes of each per 4 dimensions, with 128 * sum(d).
TEST(BruteForce, Int8LayoutPadsRowsAndColumnsToDotZero) {
  std::mt19937 rng(6);
  FeatureDescriptors a;
  for (int i = 0; i < 18; ++i) {
    const auto r = RandomSift(&rng);
    a.data.insert(a.data.end(), r.begin(), r.end());
  }
  const WideDescriptors w = WidenDescriptors(a, 17, DotKernel::kInt8Vnni512);
  EXPECT_EQ(w.rows, 17u);
  EXPECT_EQ(w.signed_rows.size(), 20u * kDescriptorDim);
  EXPECT_EQ(w.column_sums.size(), 32u);
  EXPECT_EQ(w.columns.size(), 32u * kDescriptorDim);
  int sum = 0;
  for (int d = 0; d < kDescriptorDim; ++d) {
    EXPECT_EQ(w.signed_rows[16 * kDescriptorDim + d], int(a.row(16)[d]) - 128);
    EXPECT_EQ(w.signed_rows[17 * kDescriptorDim + d], -128);
    // Feature 16 is lane 0 of the second group.
    EXPECT_EQ(w.columns[16 * kDescriptorDim + (d / 4) * 64 + d % 4], a.row(16)[d]);
    sum += a.row(16)[d];
  }
  EXPECT_EQ(w.column_sums[16], 128 * sum);
  EXPECT_EQ(w.column_sums[17], 0);
}

TEST(BruteForce, TheBestKernelIsAvailable) {
  EXPECT_TRUE(DotKernelAvailable(BestDotKernel())) << DotKernelName(BestDotKernel());
  EXPECT_TRUE(DotKernelAvailable(DotKernel::kInt16Avx2));
}

}  // namespace
}  // namespace cashash
