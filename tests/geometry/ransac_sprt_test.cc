// The sequential test of ransac_sprt.h on simulated inlier sequences: a model
// as good as the best so far is rejected at most max_risk of the time, a
// wrong model within a few dozen matches; the spread order visits every
// match once; the test stays off where it cannot pay.
#include "cashash/geometry/ransac_sprt.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

#include "cashash/geometry/random_sampler.h"

namespace cashash {
namespace {

struct Outcome {
  double rejected_share = 0;
  double mean_matches_read = 0;  // over the rejected models
};

// `runs` models whose matches are inliers with probability `rate`, under
// the test for must_reach of n.
Outcome Simulate(double rate, int must_reach, int n, float max_risk, int runs, uint64_t seed) {
  const SprtTest t = MakeSprtTest(must_reach, n, max_risk);
  EXPECT_TRUE(t.active);
  const int step = SprtOrderStep(n);
  SplitMix64 rng(seed);
  std::vector<char> inlier(n);
  int rejected = 0;
  double read = 0;
  for (int r = 0; r < runs; ++r) {
    for (int i = 0; i < n; ++i) inlier[i] = static_cast<double>(rng.Next() >> 11) * 0x1.0p-53 < rate;
    int count = 0;
    const bool rejects = SprtRejects(t, n, static_cast<int>(rng.Below(static_cast<uint32_t>(n))), step, [&](int i) {
      ++count;
      return inlier[i] != 0;
    });
    if (rejects) {
      ++rejected;
      read += count;
    }
  }
  Outcome o;
  o.rejected_share = static_cast<double>(rejected) / runs;
  o.mean_matches_read = rejected > 0 ? read / rejected : 0;
  return o;
}

TEST(RansacSprt, ModelsThatWouldBeatTheBestAreRarelyRejected) {
  // eps = 0.37, as on the 300-image street's pairs; Ville's bound is 1 %.
  for (const double rate : {0.37, 0.45, 0.6}) {
    const Outcome o = Simulate(rate, 1110, 3000, 0.01f, 20000, 7);
    EXPECT_LE(o.rejected_share, 0.012) << "rate " << rate;
  }
  // A small best (eps = 0.12) with the default risk.
  EXPECT_LE(Simulate(0.12, 120, 1000, 0.001f, 20000, 8).rejected_share, 0.002);
}

TEST(RansacSprt, WrongModelsGoWithinAFewDozenMatches) {
  for (const double rate : {0.0, 0.05, 0.15}) {
    const Outcome o = Simulate(rate, 1110, 3000, 0.001f, 5000, 9);
    EXPECT_GE(o.rejected_share, 0.999) << "rate " << rate;
    EXPECT_LT(o.mean_matches_read, rate < 0.1 ? 40 : 100) << "rate " << rate;
  }
}

TEST(RansacSprt, OffWhereItCannotPay) {
  EXPECT_FALSE(MakeSprtTest(0, 1000, 0.001f).active);      // no best yet: every model counts
  EXPECT_FALSE(MakeSprtTest(500, 1000, 0.f).active);       // switched off
  EXPECT_FALSE(MakeSprtTest(500, 1000, 1.f).active);
  EXPECT_FALSE(MakeSprtTest(30, 1000, 0.001f).active);     // eps 0.03: a null model needs > 128 matches
  EXPECT_FALSE(MakeSprtTest(1000, 1000, 0.001f).active);   // nothing can beat it
  EXPECT_FALSE(MakeSprtTest(10, 20, 0.001f).active);       // too few matches to read
  const SprtTest t = MakeSprtTest(370, 1000, 0.001f);
  EXPECT_TRUE(t.active);
  EXPECT_EQ(t.max_matches, kSprtMaxMatches);
  EXPECT_LT(t.log_inlier, 0.f);
  EXPECT_GT(t.log_outlier, 0.f);
}

// The GPU reads the matches 8 at a time (ransac.cu): the same decision as
// one at a time, for models near the boundary of the test and far from it,
// and for max_matches that are not multiples of the group.
TEST(RansacSprt, GroupedReadingDecidesAsOneAtATime) {
  SplitMix64 rng(11);
  int rejected = 0, kept = 0;
  for (const int n : {37, 300, 1001, 3000}) {
    const int step = SprtOrderStep(n);
    for (const int must_reach : {n / 3, n / 2}) {
      const SprtTest t = MakeSprtTest(must_reach, n, 0.001f);
      if (!t.active) continue;
      std::vector<char> inlier(n);
      for (int r = 0; r < 2000; ++r) {
        const double rate = (r % 8) * 0.1;
        for (int i = 0; i < n; ++i) inlier[i] = static_cast<double>(rng.Next() >> 11) * 0x1.0p-53 < rate;
        const int start = static_cast<int>(rng.Below(static_cast<uint32_t>(n)));
        const auto is_inlier = [&](int i) { return inlier[i] != 0; };
        const bool one = SprtRejects(t, n, start, step, is_inlier);
        ASSERT_EQ(one, SprtRejects<8>(t, n, start, step, is_inlier)) << "n " << n << " run " << r;
        ASSERT_EQ(one, SprtRejects<3>(t, n, start, step, is_inlier)) << "n " << n << " run " << r;
        (one ? rejected : kept) += 1;
      }
    }
  }
  EXPECT_GT(rejected, 1000);  // both outcomes were exercised
  EXPECT_GT(kept, 1000);
}

TEST(RansacSprt, SpreadOrderVisitsEveryMatchOnce) {
  for (int n = 1; n <= 3000; ++n) {
    const int step = SprtOrderStep(n);
    ASSERT_GE(step, 1);
    ASSERT_LE(step, n > 1 ? n : 1);
    std::vector<char> seen(n, 0);
    int i = n / 3;
    for (int k = 0; k < n; ++k) {
      ASSERT_FALSE(seen[i]) << "n " << n << " step " << step;
      seen[i] = 1;
      i += step;
      if (i >= n) i -= n;
    }
  }
}

}  // namespace
}  // namespace cashash
