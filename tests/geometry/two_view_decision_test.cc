// The split of EstimateTwoViewGeometry into estimation and decision (the GPU
// verifier estimates F and H itself and must decide as the CPU path does),
// and the CPU batch verifier behind the pipeline's verification stage.
#include <gtest/gtest.h>

#include "cashash/pipeline/batch_verifier.h"
#include "cashash/base/pair_id.h"
#include "cashash/geometry/two_view_geometry.h"
#include "synthetic_two_view.h"

namespace cashash {
namespace {

using testing_support::MakeScene;
using testing_support::SceneOptions;
using testing_support::SyntheticScene;

void ExpectSameGeometry(const TwoViewGeometry& a, const TwoViewGeometry& b) {
  EXPECT_EQ(a.config, b.config);
  EXPECT_EQ(a.inlier_matches, b.inlier_matches);
  EXPECT_EQ(a.F, b.F);
  EXPECT_EQ(a.H, b.H);
  EXPECT_EQ(a.E, b.E);
}

// An estimate whose first `num_inliers` matches are the inliers.
TwoViewModelEstimate FakeEstimate(size_t num_matches, int num_inliers, double marker) {
  TwoViewModelEstimate e;
  e.success = num_inliers > 0;
  e.num_inliers = num_inliers;
  e.model = Eigen::Matrix3d::Identity() * marker;
  e.inlier_mask.assign(num_matches, 0);
  for (int i = 0; i < num_inliers; ++i) e.inlier_mask[static_cast<size_t>(i)] = 1;
  return e;
}

struct DecisionCase {
  int num_F, num_H, num_E;
  bool calibrated;
  int expected_config;
  size_t expected_inliers;
};

TEST(TwoViewDecision, StepsComposeToEstimateTwoViewGeometry) {
  SceneOptions general;
  SceneOptions planar;
  planar.planar = true;
  for (const SceneOptions& scene_options : {general, planar}) {
    const SyntheticScene scene = MakeScene(scene_options);
    for (const bool priors : {false, true}) {
      const Camera camera = scene.MakeCamera(priors);
      TwoViewGeometryOptions options;
      options.random_seed = 1234;
      const TwoViewGeometry whole =
          EstimateTwoViewGeometry(camera, scene.points1, camera, scene.points2, scene.matches, options);
      const TwoViewPoints points = PrepareTwoViewPoints(scene.points1, scene.points2, scene.matches);
      const TwoViewModelEstimate F = EstimateFundamental(points, options);
      const TwoViewModelEstimate H =
          EstimateHomography(points, options, TwoViewRelevantHomographyInliers(F.success ? F.num_inliers : 0, options));
      const bool calibrated = TwoViewIsCalibrated(camera, camera);
      EXPECT_EQ(calibrated, priors);
      const TwoViewModelEstimate E =
          calibrated ? EstimateEssential(camera, camera, points.pixels, options,
                                         TwoViewEssentialSettledInliers(F.success ? F.num_inliers : 0,
                                                                    H.success ? H.num_inliers : 0,
                                                                    static_cast<int>(scene.matches.size()), options))
                     : TwoViewModelEstimate();
      const TwoViewGeometry steps =
          DecideTwoViewGeometry(camera, camera, points.pixels, scene.matches, calibrated, F, H, E, options);
      ExpectSameGeometry(whole, steps);
      EXPECT_GT(F.num_trials, 0);
      EXPECT_NEAR(NormalizedSquaredThreshold(points, options),
                  16.0 * points.norm.scale * points.norm.scale, 1e-12);
    }
  }
}

TEST(TwoViewDecision, ConfigurationFromInlierCounts) {
  // Matches spread over the middle of a 1000 x 1000 image: no watermark.
  const size_t n = 200;
  PointPairs pixels;
  pixels.resize(n);
  FeatureMatches matches(n);
  for (size_t i = 0; i < n; ++i) {
    const double x = 300 + static_cast<double>(i % 20) * 20, y = 300 + static_cast<double>(i / 20) * 40;
    pixels.Set(i, x, y, x + 5, y);
    matches[i].point2D_idx1 = matches[i].point2D_idx2 = static_cast<point2D_t>(i);
  }
  Camera camera;
  camera.width = camera.height = 1000;
  camera.params = {1000, 500, 500};
  const std::vector<DecisionCase> cases = {
      {100, 50, 0, false, kUncalibrated, 100},
      {100, 81, 0, false, kPlanarOrPanoramic, 100},   // H/F > 0.8, H smaller: F's inliers
      {100, 100, 0, false, kPlanarOrPanoramic, 100},  // a tie keeps H's (same count here)
      {10, 20, 0, false, kPlanarOrPanoramic, 20},     // F below min_num_inliers: H alone
      {10, 10, 0, false, kDegenerate, 0},
      {100, 50, 97, true, kCalibrated, 100},          // E/F > 0.95: the larger of E and F
      {100, 50, 120, true, kCalibrated, 120},
      {100, 50, 90, true, kUncalibrated, 100},        // E/F too low: falls back to F
      {100, 110, 100, true, kPlanarOrPanoramic, 110}, // H/E > 0.8 and H larger: H's inliers
      {100, 50, 120, false, kUncalibrated, 100},      // E ignored without priors
  };
  const TwoViewGeometryOptions options;
  for (const DecisionCase& c : cases) {
    const TwoViewModelEstimate F = FakeEstimate(n, c.num_F, 1);
    const TwoViewModelEstimate H = FakeEstimate(n, c.num_H, 2);
    const TwoViewModelEstimate E = FakeEstimate(n, c.num_E, 3);
    const TwoViewGeometry g = DecideTwoViewGeometry(camera, camera, pixels, matches, c.calibrated, F, H, E, options);
    SCOPED_TRACE(testing::Message() << "F " << c.num_F << " H " << c.num_H << " E " << c.num_E << " calibrated "
                                    << c.calibrated);
    EXPECT_EQ(g.config, c.expected_config);
    EXPECT_EQ(g.inlier_matches.size(), c.expected_inliers);
    EXPECT_EQ(g.F(0, 0), c.num_F > 0 ? 1.0 : 0.0);
    EXPECT_EQ(g.E(0, 0), c.calibrated && c.num_E > 0 ? 3.0 : 0.0);
  }
}

TEST(TwoViewDecision, TooFewMatchesNeedsNoEstimates) {
  TwoViewGeometryOptions options;
  EXPECT_TRUE(TooFewMatchesForTwoView(14, options));
  EXPECT_FALSE(TooFewMatchesForTwoView(15, options));
  options.min_num_inliers = 0;
  EXPECT_FALSE(TooFewMatchesForTwoView(0, options));
}

TEST(CpuBatchVerifier, SameAsOnePairAtATimeWithThePairSeed) {
  std::vector<SyntheticScene> scenes;
  for (unsigned seed = 1; seed <= 6; ++seed) {
    SceneOptions o;
    o.seed = seed;
    o.num_inliers = 150 + 40 * static_cast<int>(seed);
    o.outlier_ratio = 0.1 * seed;
    o.planar = seed == 3;
    scenes.push_back(MakeScene(o));
  }
  const Camera with_prior = scenes[0].MakeCamera(true), without = scenes[0].MakeCamera(false);
  TwoViewGeometryOptions options;
  options.random_seed = 99;
  std::vector<VerificationPair> pairs(scenes.size());
  for (size_t k = 0; k < scenes.size(); ++k) {
    pairs[k].camera1 = pairs[k].camera2 = k % 2 ? &with_prior : &without;
    pairs[k].points1 = &scenes[k].points1;
    pairs[k].points2 = &scenes[k].points2;
    pairs[k].matches = &scenes[k].matches;
    pairs[k].random_seed = PairRandomSeed(options.random_seed, ImagePair(static_cast<image_t>(k + 1), 100));
  }
  const std::vector<TwoViewGeometry> batch = CreateCpuBatchVerifier(options, 3)->Verify(pairs);
  ASSERT_EQ(batch.size(), pairs.size());
  for (size_t k = 0; k < pairs.size(); ++k) {
    TwoViewGeometryOptions pair_options = options;
    pair_options.random_seed = pairs[k].random_seed;
    ExpectSameGeometry(batch[k], EstimateTwoViewGeometry(*pairs[k].camera1, scenes[k].points1, *pairs[k].camera2,
                                                         scenes[k].points2, scenes[k].matches, pair_options));
    EXPECT_GE(batch[k].config, kCalibrated);
  }
}

TEST(CpuBatchVerifier, PairSeedDependsOnThePairNotItsOrder) {
  EXPECT_EQ(PairRandomSeed(5, ImagePair(1, 2)), PairRandomSeed(5, ImagePair(2, 1)));
  EXPECT_NE(PairRandomSeed(5, ImagePair(1, 2)), PairRandomSeed(5, ImagePair(1, 3)));
  EXPECT_NE(PairRandomSeed(5, ImagePair(1, 2)), PairRandomSeed(6, ImagePair(1, 2)));
}

}  // namespace
}  // namespace cashash
