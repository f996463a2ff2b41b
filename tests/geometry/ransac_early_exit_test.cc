// The early exit of RANSAC (ransac_early_exit.h): its binomial tail, that a
// pair of pure chance matches stops long before the trial cap with the
// decision of the full budget, that pairs with a real model run exactly
// as COLMAP's loop, and that H and E stop where they can no longer change
// the decision. Real pairs from ../shared are checked against the full
// budget by tests/integration/early_exit_real_pairs.sh.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <utility>

#include "cashash/geometry/fundamental_matrix.h"
#include "cashash/geometry/ransac.h"
#include "cashash/geometry/ransac_early_exit.h"
#include "cashash/geometry/two_view_geometry.h"
#include "synthetic_two_view.h"

namespace cashash {
namespace {

using testing_support::MakeScene;
using testing_support::SceneOptions;
using testing_support::SyntheticScene;

double DirectUpperTail(int n, double p, int k) {
  double sum = 0;
  for (int x = k; x <= n; ++x) {
    sum += std::exp(std::lgamma(n + 1.0) - std::lgamma(x + 1.0) - std::lgamma(n - x + 1.0) + x * std::log(p) +
                    (n - x) * std::log1p(-p));
  }
  return sum;
}

TEST(RansacEarlyExit, BinomialUpperTailMatchesTheDirectSum) {
  for (int n : {10, 50, 300, 5000}) {
    for (double p : {0.001, 0.01, 0.05}) {
      for (int k : {3, 8, 15}) {
        if (k <= n * p) continue;
        const double expected = DirectUpperTail(n, p, k);
        EXPECT_NEAR(BinomialUpperTail(n, p, k), expected, 1e-9 * std::max(1.0, expected) + 1e-300)
            << n << " " << p << " " << k;
      }
    }
  }
  EXPECT_EQ(BinomialUpperTail(10, 0.5, 0), 1.0);
  EXPECT_EQ(BinomialUpperTail(10, 0.5, 11), 0.0);
  EXPECT_EQ(BinomialUpperTail(100, 0.5, 30), 1.0);  // at or below the mean: reported as 1
}

TEST(RansacEarlyExit, DeltaFromBestSupportMakesTheBestAOneInKEvent) {
  const double delta = DeltaFromBestSupport(200, 6, 1000.0);
  EXPECT_NEAR(BinomialUpperTail(200, delta, 6), 1e-3, 1e-4);
}

TEST(RansacEarlyExit, CheckpointsAreTheWindowAndItsDoublings) {
  RansacEarlyExitOptions options;
  options.min_num_inliers = 15;
  options.window = 256;
  EXPECT_FALSE(RansacEarlyExitCheckpoint(options, 128));
  EXPECT_TRUE(RansacEarlyExitCheckpoint(options, 256));
  EXPECT_FALSE(RansacEarlyExitCheckpoint(options, 384));
  EXPECT_TRUE(RansacEarlyExitCheckpoint(options, 512));
  EXPECT_TRUE(RansacEarlyExitCheckpoint(options, 2048));
  options.min_num_inliers = 0;
  EXPECT_FALSE(RansacEarlyExitCheckpoint(options, 256));
}

// Matches between two unrelated images: uniform random positions.
SyntheticScene ChanceScene(int num_matches, unsigned seed) {
  SceneOptions options;
  options.num_inliers = 0;
  options.outlier_ratio = 0.0;
  SyntheticScene scene = MakeScene(options);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> x(0, scene.width), y(0, scene.height);
  for (int i = 0; i < num_matches; ++i) {
    // y before x, one draw a statement (ordered_draws.h).
    const double y1 = y(rng);
    scene.points1.emplace_back(x(rng), y1);
    const double y2 = y(rng);
    scene.points2.emplace_back(x(rng), y2);
    scene.matches.push_back({static_cast<point2D_t>(i), static_cast<point2D_t>(i)});
    scene.is_inlier.push_back(false);
  }
  return scene;
}

TwoViewGeometryOptions Options(bool early_exit) {
  TwoViewGeometryOptions options;
  options.early_exit = early_exit;
  return options;
}

TEST(RansacEarlyExit, PureChanceMatchesStopEarlyWithTheFullBudgetsDecision) {
  // Larger chance pairs run on: 80 uniform matches give supports whose tail
  // reaches 15 inliers within the budget with more than max_risk.
  // One seed a size: each case runs COLMAP's full trial budget twice.
  for (const auto& [num_matches, seed] : {std::pair{20, 1u}, std::pair{30, 2u}, std::pair{45, 3u}}) {
    const SyntheticScene scene = ChanceScene(num_matches, seed);
    const TwoViewPoints points = PrepareTwoViewPoints(scene.points1, scene.points2, scene.matches);
    const TwoViewModelEstimate full = EstimateFundamental(points, Options(false));
    const TwoViewModelEstimate early = EstimateFundamental(points, Options(true));
    EXPECT_TRUE(early.early_exit) << num_matches << " matches, seed " << seed;
    EXPECT_FALSE(full.early_exit);
    EXPECT_LE(early.num_trials, 2048) << num_matches << " matches, seed " << seed;
    EXPECT_LT(early.num_trials, full.num_trials);
    EXPECT_LT(full.num_inliers, 15);
    EXPECT_LT(early.num_inliers, 15);

    const Camera camera = scene.MakeCamera(/*prior=*/true);
    const TwoViewGeometry a =
        EstimateTwoViewGeometry(camera, scene.points1, camera, scene.points2, scene.matches, Options(false));
    const TwoViewGeometry b =
        EstimateTwoViewGeometry(camera, scene.points1, camera, scene.points2, scene.matches, Options(true));
    EXPECT_EQ(a.config, kDegenerate);
    EXPECT_EQ(b.config, a.config);
  }
}

TEST(RansacEarlyExit, PairsWithAModelRunAsTheFullBudget) {
  for (double outlier_ratio : {0.3, 0.6}) {
    SceneOptions options;
    options.num_inliers = 120;
    options.outlier_ratio = outlier_ratio;
    const SyntheticScene scene = MakeScene(options);
    const TwoViewPoints points = PrepareTwoViewPoints(scene.points1, scene.points2, scene.matches);
    const TwoViewModelEstimate full = EstimateFundamental(points, Options(false));
    const TwoViewModelEstimate early = EstimateFundamental(points, Options(true));
    // Same trials, same model: the exit never fired and the window's full
    // scoring changed no comparison.
    EXPECT_EQ(early.num_trials, full.num_trials);
    EXPECT_EQ(early.num_inliers, full.num_inliers);
    EXPECT_TRUE(early.model.isApprox(full.model));
    const Camera camera = scene.MakeCamera(true);
    const TwoViewGeometry a =
        EstimateTwoViewGeometry(camera, scene.points1, camera, scene.points2, scene.matches, Options(false));
    const TwoViewGeometry b =
        EstimateTwoViewGeometry(camera, scene.points1, camera, scene.points2, scene.matches, Options(true));
    EXPECT_EQ(b.config, a.config);
    EXPECT_EQ(b.inlier_matches.size(), a.inlier_matches.size());
  }
}

// H only matters above 0.8 x 0.95 of F's inliers (or of min_num_inliers
// when F fails): below, it stops once such a model would have been found.
TEST(RansacEarlyExit, RelevantHomographyInliersFollowTheDecisionRule) {
  TwoViewGeometryOptions options;
  EXPECT_EQ(TwoViewRelevantHomographyInliers(1000, options), 760);
  EXPECT_EQ(TwoViewRelevantHomographyInliers(0, options), 12);  // ceil(0.76 x 15)
  EXPECT_EQ(TwoViewRelevantHomographyInliers(5, options), 12);
  options.early_exit = false;
  EXPECT_EQ(TwoViewRelevantHomographyInliers(1000, options), 0);
}

TEST(RansacEarlyExit, HomographyStopsWhenItCannotChangeTheDecision) {
  for (const bool planar : {false, true}) {
    SceneOptions o;
    o.planar = planar;
    o.num_inliers = 400;
    o.outlier_ratio = 0.2;
    const SyntheticScene scene = MakeScene(o);
    const TwoViewPoints points = PrepareTwoViewPoints(scene.points1, scene.points2, scene.matches);
    const TwoViewGeometryOptions options = Options(true);
    const TwoViewModelEstimate F = EstimateFundamental(points, options);
    const int relevant = TwoViewRelevantHomographyInliers(F.num_inliers, options);
    const TwoViewModelEstimate full_H = EstimateHomography(points, options);
    const TwoViewModelEstimate H = EstimateHomography(points, options, relevant);
    if (planar) {
      // A plane explains the matches: H runs as COLMAP's loop.
      EXPECT_GE(full_H.num_inliers, relevant);
      EXPECT_EQ(H.num_trials, full_H.num_trials);
      EXPECT_EQ(H.num_inliers, full_H.num_inliers);
    } else {
      EXPECT_LT(full_H.num_inliers, relevant);
      EXPECT_TRUE(H.early_exit);
      EXPECT_LT(H.num_trials, full_H.num_trials);
    }
    const Camera camera = scene.MakeCamera(false);
    const TwoViewGeometry a =
        EstimateTwoViewGeometry(camera, scene.points1, camera, scene.points2, scene.matches, Options(false));
    const TwoViewGeometry b =
        EstimateTwoViewGeometry(camera, scene.points1, camera, scene.points2, scene.matches, Options(true));
    EXPECT_EQ(b.config, a.config) << (planar ? "planar" : "general");
    EXPECT_EQ(b.inlier_matches.size(), a.inlier_matches.size());
  }
}

// E's settled count against the decision's own tests, by brute force: the
// first count from which every larger one is CALIBRATED (more than
// min_E_F_inlier_ratio x F's, at least min_num_inliers, H / E at most
// max_H_inlier_ratio).
void ExpectSettledInliersFollowTheDecisionRule(const TwoViewGeometryOptions& options) {
  auto calibrated = [&](int e, int num_F, int num_H) {
    const double e_f = static_cast<double>(e) / num_F;  // infinite when F failed, as in the decision
    const double h_e = static_cast<double>(num_H) / e;
    return e > 0 && e_f > options.min_E_F_inlier_ratio && e >= options.min_num_inliers &&
           !(h_e > options.max_H_inlier_ratio);
  };
  const int num_matches = 400;
  for (int num_F : {0, 1, 14, 15, 16, 20, 40, 60, 100, 399}) {
    for (int num_H : {0, 5, 12, 16, 30, 48, 100, 380}) {
      const int settled = TwoViewEssentialSettledInliers(num_F, num_H, num_matches, options);
      int first = 0;
      for (int e = 1; e <= num_matches && first == 0; ++e) {
        if (calibrated(e, num_F, num_H)) first = e;
      }
      EXPECT_EQ(settled, first) << "F " << num_F << ", H " << num_H;
      for (int e = first; first > 0 && e <= num_matches; ++e) {
        ASSERT_TRUE(calibrated(e, num_F, num_H)) << "F " << num_F << ", H " << num_H << ", E " << e;
      }
    }
  }
}

TEST(RansacEarlyExit, EssentialSettledInliersFollowTheDecisionRule) {
  TwoViewGeometryOptions zero_H_ratio;
  zero_H_ratio.max_H_inlier_ratio = 0;  // the option's edge: no H inlier is allowed at all
  for (const TwoViewGeometryOptions& options : {TwoViewGeometryOptions(), zero_H_ratio}) {
    SCOPED_TRACE(testing::Message() << "max_H_inlier_ratio " << options.max_H_inlier_ratio);
    ASSERT_NO_FATAL_FAILURE(ExpectSettledInliersFollowTheDecisionRule(options));
  }
  const TwoViewGeometryOptions options;
  const int num_matches = 400;
  EXPECT_EQ(TwoViewEssentialSettledInliers(40, 5, num_matches, options), 39);  // 39 / 40 > 0.95
  EXPECT_EQ(TwoViewEssentialSettledInliers(0, 0, num_matches, options), 15);
  EXPECT_EQ(TwoViewEssentialSettledInliers(399, 5, num_matches, options), 380);
  EXPECT_EQ(TwoViewEssentialSettledInliers(399, 390, num_matches, options), 0);  // H / E > 0.8 up to 400
  EXPECT_EQ(TwoViewEssentialSettledInliers(40, 0, num_matches, zero_H_ratio), 39);
  EXPECT_EQ(TwoViewEssentialSettledInliers(40, 1, num_matches, zero_H_ratio), 0);
  TwoViewGeometryOptions off = options;
  off.early_exit = false;
  EXPECT_EQ(TwoViewEssentialSettledInliers(40, 5, num_matches, off), 0);
}

// A calibrated pair of low inlier ratio, where COLMAP's loop runs E to the
// trial cap: E stops once F's and H's counts settle the decision, with the
// full budget's configuration and nearly all of its inliers.
TEST(RansacEarlyExit, EssentialStopsOnceTheDecisionIsSettled) {
  int stopped = 0;
  for (unsigned seed : {3u, 7u, 11u, 19u}) {
    SceneOptions o;
    o.num_inliers = 50;
    o.outlier_ratio = 0.78;  // about 230 matches, an inlier ratio of 0.22
    o.seed = seed;
    const SyntheticScene scene = MakeScene(o);
    const Camera camera = scene.MakeCamera(/*prior=*/true);
    const TwoViewPoints points = PrepareTwoViewPoints(scene.points1, scene.points2, scene.matches);
    TwoViewGeometryOptions options = Options(true);
    options.random_seed = seed;
    const TwoViewModelEstimate F = EstimateFundamental(points, options);
    const TwoViewModelEstimate H =
        EstimateHomography(points, options, TwoViewRelevantHomographyInliers(F.success ? F.num_inliers : 0, options));
    const int settled = TwoViewEssentialSettledInliers(F.success ? F.num_inliers : 0, H.success ? H.num_inliers : 0,
                                                       static_cast<int>(scene.matches.size()), options);
    const TwoViewModelEstimate full_E = EstimateEssential(camera, camera, points.pixels, options);
    const TwoViewModelEstimate E = EstimateEssential(camera, camera, points.pixels, options, settled);
    SCOPED_TRACE(testing::Message() << "seed " << seed << ": F " << F.num_inliers << ", H " << H.num_inliers
                                    << ", E " << E.num_inliers << " in " << E.num_trials << " trials, full "
                                    << full_E.num_inliers << " in " << full_E.num_trials << ", settled at "
                                    << settled);
    EXPECT_GT(settled, 0);
    EXPECT_EQ(full_E.num_trials, options.max_num_trials);  // COLMAP's loop runs to the cap here
    if (E.num_trials < full_E.num_trials) {
      ++stopped;
      EXPECT_TRUE(E.early_exit);
      EXPECT_GE(E.num_inliers, settled);
      EXPECT_GE(E.num_trials, options.min_num_trials);
    }
    EXPECT_GE(E.num_inliers, full_E.num_inliers - 5);
    TwoViewGeometryOptions full = Options(false);
    full.random_seed = seed;
    const TwoViewGeometry a = EstimateTwoViewGeometry(camera, scene.points1, camera, scene.points2, scene.matches, full);
    const TwoViewGeometry b =
        EstimateTwoViewGeometry(camera, scene.points1, camera, scene.points2, scene.matches, options);
    EXPECT_EQ(a.config, kCalibrated);
    EXPECT_EQ(b.config, a.config);
    EXPECT_GE(b.inlier_matches.size() + 5, a.inlier_matches.size());
  }
  EXPECT_GE(stopped, 3);
}

TEST(RansacEarlyExit, OptionIsChecked) {
  TwoViewGeometryOptions options;
  options.early_exit_max_risk = 0;
  EXPECT_NE(options.Check().find("early_exit_max_risk"), std::string::npos);
}

}  // namespace
}  // namespace cashash
