#include "cashash/geometry/two_view_geometry.h"

#include <gtest/gtest.h>


#include <Eigen/Dense>
#include <Eigen/Geometry>

#include "cashash/geometry/camera_projection.h"
#include "cashash/geometry/ransac.h"
#include "ordered_draws.h"
#include "synthetic_two_view.h"

namespace cashash {
namespace {

using testing_support::MakeScene;
using testing_support::SceneOptions;
using testing_support::SyntheticScene;

TwoViewGeometry Verify(const SyntheticScene& scene, bool priors,
                       const TwoViewGeometryOptions& options = TwoViewGeometryOptions()) {
  return EstimateTwoViewGeometry(scene.MakeCamera(priors), scene.points1, scene.MakeCamera(priors),
                                 scene.points2, scene.matches, options);
}

// Fraction of the true inliers kept, and number of outliers kept.
std::pair<double, int> InlierRecall(const SyntheticScene& scene, const TwoViewGeometry& g) {
  int true_total = 0, true_kept = 0, outliers_kept = 0;
  std::vector<bool> kept(scene.points1.size(), false);
  for (const auto& m : g.inlier_matches) kept[m.point2D_idx1] = true;
  for (size_t i = 0; i < scene.matches.size(); ++i) {
    const bool k = kept[scene.matches[i].point2D_idx1];
    true_total += scene.is_inlier[i];
    if (k) (scene.is_inlier[i] ? true_kept : outliers_kept)++;
  }
  return {static_cast<double>(true_kept) / true_total, outliers_kept};
}

bool IsSubsequence(const FeatureMatches& sub, const FeatureMatches& all) {
  size_t j = 0;
  for (const auto& m : all) {
    if (j < sub.size() && sub[j] == m) ++j;
  }
  return j == sub.size();
}

// TwoViewGeometryOptions holds the RANSAC settings a user gives
// (TwoViewGeometry.*) and RansacOptions those of one estimator run, as
// COLMAP's TwoViewGeometryOptions and RANSACOptions; the verification copies
// the first into the second. Their defaults are one set: COLMAP's
// two-view ones.
TEST(TwoViewGeometry, RansacDefaultsAreTheTwoViewDefaults) {
  const TwoViewGeometryOptions two_view;
  const RansacOptions ransac;
  EXPECT_EQ(ransac.max_error, two_view.max_error);
  EXPECT_EQ(ransac.confidence, two_view.confidence);
  EXPECT_EQ(ransac.min_num_trials, two_view.min_num_trials);
  EXPECT_EQ(ransac.max_num_trials, two_view.max_num_trials);
  EXPECT_EQ(ransac.min_inlier_ratio, two_view.min_inlier_ratio);
}

TEST(TwoViewGeometry, GeneralSceneWithPriorsIsCalibrated) {
  const auto scene = MakeScene(SceneOptions());
  const TwoViewGeometry g = Verify(scene, true);
  EXPECT_EQ(g.config, kCalibrated);
  const auto [recall, outliers] = InlierRecall(scene, g);
  EXPECT_GT(recall, 0.95);
  EXPECT_LT(outliers, 15);
  EXPECT_TRUE(IsSubsequence(g.inlier_matches, scene.matches));
  EXPECT_FALSE(g.E.isZero(0));
  EXPECT_FALSE(g.F.isZero(0));
  EXPECT_FALSE(g.H.isZero(0));
  // E agrees with the truth up to scale and sign.
  Eigen::Matrix3d truth = scene.TrueE();
  truth /= truth.norm();
  const Eigen::Matrix3d E = g.E / g.E.norm();
  EXPECT_LT(std::min((E - truth).norm(), (E + truth).norm()), 0.02);
  // F of the pixels is consistent with E and K.
  const Eigen::Matrix3d Kinv = scene.K.inverse();
  Eigen::Matrix3d F_from_E = Kinv.transpose() * g.E * Kinv;
  F_from_E /= F_from_E.norm();
  EXPECT_LT(std::min((g.F - F_from_E).norm(), (g.F + F_from_E).norm()), 0.05);
}

TEST(TwoViewGeometry, GeneralSceneWithoutPriorsIsUncalibrated) {
  const auto scene = MakeScene(SceneOptions());
  const TwoViewGeometry g = Verify(scene, false);
  EXPECT_EQ(g.config, kUncalibrated);
  EXPECT_TRUE(g.E.isZero(0));
  const auto [recall, outliers] = InlierRecall(scene, g);
  EXPECT_GT(recall, 0.95);
  EXPECT_LT(outliers, 15);
}

TEST(TwoViewGeometry, WrongFocalPriorFallsBackToF) {
  const auto scene = MakeScene(SceneOptions());
  Camera camera = scene.MakeCamera(true);
  camera.params[0] = camera.params[1] = 2500;  // far from the true 1000
  const TwoViewGeometry g = EstimateTwoViewGeometry(camera, scene.points1, camera, scene.points2,
                                                    scene.matches, TwoViewGeometryOptions());
  EXPECT_EQ(g.config, kUncalibrated);
  EXPECT_GT(InlierRecall(scene, g).first, 0.95);
}

TEST(TwoViewGeometry, DistortedCameraIsUndistortedForE) {
  // Re-render the scene through a SIMPLE_RADIAL lens: E must be estimated
  // on undistorted coordinates to explain the matches.
  auto scene = MakeScene(SceneOptions());
  Camera camera;
  camera.model_id = 2;  // SIMPLE_RADIAL
  camera.width = scene.width;
  camera.height = scene.height;
  camera.params = {scene.K(0, 0), scene.K(0, 2), scene.K(1, 2), -0.12};
  camera.has_prior_focal_length = true;
  for (auto* points : {&scene.points1, &scene.points2}) {
    for (Eigen::Vector2d& p : *points) {
      const Eigen::Vector3d ray = scene.K.inverse() * p.homogeneous();
      CameraWorldToImage(camera, ray.x(), ray.y(), &p.x(), &p.y());
    }
  }
  const TwoViewGeometry g = EstimateTwoViewGeometry(camera, scene.points1, camera, scene.points2,
                                                    scene.matches, TwoViewGeometryOptions());
  EXPECT_EQ(g.config, kCalibrated);
  EXPECT_GT(InlierRecall(scene, g).first, 0.95);
}

TEST(TwoViewGeometry, PlanarSceneIsPlanarOrPanoramic) {
  SceneOptions opts;
  opts.planar = true;
  const auto scene = MakeScene(opts);
  for (const bool priors : {false, true}) {
    const TwoViewGeometry g = Verify(scene, priors);
    EXPECT_EQ(g.config, kPlanarOrPanoramic) << "priors " << priors;
    EXPECT_GT(InlierRecall(scene, g).first, 0.95);
  }
}

TEST(TwoViewGeometry, PureRotationIsPlanarOrPanoramic) {
  SceneOptions opts;
  opts.baseline = 0;
  const auto scene = MakeScene(opts);
  EXPECT_EQ(Verify(scene, false).config, kPlanarOrPanoramic);
}

TEST(TwoViewGeometry, TooFewMatchesIsDegenerate) {
  SceneOptions opts;
  opts.num_inliers = 14;
  opts.outlier_ratio = 0;
  const auto scene = MakeScene(opts);
  const TwoViewGeometry g = Verify(scene, true);
  EXPECT_EQ(g.config, kDegenerate);
  EXPECT_TRUE(g.inlier_matches.empty());
  EXPECT_TRUE(g.F.isZero(0));
}

TEST(TwoViewGeometry, BorderTranslationIsWatermark) {
  // A logo in the lower-left corner, at the same place in both images.
  SyntheticScene scene;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> corner(10.0, 150.0);
  for (int i = 0; i < 60; ++i) {
    const auto c = testing_support::DrawLastFirst<2>([&] { return corner(rng); });
    const Eigen::Vector2d p(c[0], 960 - c[1]);
    scene.points1.push_back(p);
    scene.points2.push_back(p + Eigen::Vector2d(0.2, -0.1));
    FeatureMatch m;
    m.point2D_idx1 = m.point2D_idx2 = static_cast<point2D_t>(i);
    scene.matches.push_back(m);
  }
  const TwoViewGeometry g = Verify(scene, false);
  EXPECT_EQ(g.config, kWatermark);
  EXPECT_EQ(g.inlier_matches.size(), 60u);

  TwoViewGeometryOptions no_watermark;
  no_watermark.detect_watermark = false;
  EXPECT_EQ(Verify(scene, false, no_watermark).config, kPlanarOrPanoramic);
}

TEST(TwoViewGeometry, SameSeedSameGeometry) {
  const auto scene = MakeScene(SceneOptions());
  TwoViewGeometryOptions options;
  options.random_seed = 77;
  const TwoViewGeometry a = Verify(scene, true, options);
  const TwoViewGeometry b = Verify(scene, true, options);
  EXPECT_EQ(a.config, b.config);
  EXPECT_EQ(a.inlier_matches, b.inlier_matches);
  EXPECT_EQ(a.F, b.F);
  EXPECT_EQ(a.E, b.E);
  EXPECT_EQ(a.H, b.H);
}

TEST(TwoViewGeometry, InvertedSwapsTheViews) {
  TwoViewGeometry g;
  g.config = kCalibrated;
  g.F << 0.1, -0.2, 0.3, 0.4, 0.05, -0.6, 0.7, 0.8, 0.09;
  g.E << 0.0, -0.3, 0.2, 0.3, 0.0, -0.1, -0.2, 0.1, 0.0;
  g.H << 1.1, 0.1, 5, -0.05, 0.9, 3, 1e-4, 2e-4, 1;
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  g.qvec << q.w(), q.x(), q.y(), q.z();
  g.tvec << 0.5, -0.2, 1.0;
  FeatureMatch m;
  m.point2D_idx1 = 3;
  m.point2D_idx2 = 8;
  g.inlier_matches = {m};

  const TwoViewGeometry inv = g.Inverted();
  EXPECT_EQ(inv.config, g.config);
  EXPECT_TRUE(inv.F.isApprox(g.F.transpose()));
  EXPECT_TRUE(inv.E.isApprox(g.E.transpose()));
  EXPECT_TRUE((inv.H * g.H).isApprox(Eigen::Matrix3d::Identity()));
  ASSERT_EQ(inv.inlier_matches.size(), 1u);
  EXPECT_EQ(inv.inlier_matches[0].point2D_idx1, 8u);
  EXPECT_EQ(inv.inlier_matches[0].point2D_idx2, 3u);
  // cam1_from_cam2 composed with cam2_from_cam1 is the identity.
  const Eigen::Matrix3d R = q.toRotationMatrix();
  const Eigen::Matrix3d R_inv =
      Eigen::Quaterniond(inv.qvec(0), inv.qvec(1), inv.qvec(2), inv.qvec(3)).toRotationMatrix();
  EXPECT_TRUE((R_inv * R).isApprox(Eigen::Matrix3d::Identity()));
  EXPECT_LT((R_inv * g.tvec + inv.tvec).norm(), 1e-12);

  const TwoViewGeometry back = inv.Inverted();
  EXPECT_TRUE(back.F.isApprox(g.F));
  EXPECT_TRUE(back.H.isApprox(g.H));
  EXPECT_TRUE(back.qvec.isApprox(g.qvec));
  EXPECT_TRUE(back.tvec.isApprox(g.tvec));
  EXPECT_EQ(back.inlier_matches, g.inlier_matches);

  // An unset H stays zero rather than becoming NaN.
  TwoViewGeometry empty;
  EXPECT_TRUE(empty.Inverted().H.isZero(0));
}

TEST(TwoViewGeometry, CheckNamesTheBadOption) {
  EXPECT_EQ(TwoViewGeometryOptions().Check(), "");
  TwoViewGeometryOptions o;
  o.max_error = 0;
  EXPECT_EQ(o.Check(), "TwoViewGeometry.max_error must be > 0");
  o = TwoViewGeometryOptions();
  o.confidence = 1.5;
  EXPECT_EQ(o.Check(), "TwoViewGeometry.confidence must be in [0, 1]");
  o = TwoViewGeometryOptions();
  o.min_num_inliers = -1;
  EXPECT_EQ(o.Check(), "TwoViewGeometry.min_num_inliers must be >= 0");
  o = TwoViewGeometryOptions();
  o.max_H_inlier_ratio = -0.1;
  EXPECT_EQ(o.Check(), "TwoViewGeometry.max_H_inlier_ratio must be in [0, 1]");
  o = TwoViewGeometryOptions();
  o.min_num_trials = 20000;
  EXPECT_EQ(o.Check(), "TwoViewGeometry.max_num_trials must be >= min_num_trials");
}

// A typical pair: 2000 matches, half of them wrong. Its time:
// scripts/bench/two_view_geometry_bench.
TEST(TwoViewGeometry, TypicalPairWithHalfTheMatchesWrong) {
  SceneOptions opts;
  opts.num_inliers = 1000;
  opts.outlier_ratio = 0.5;
  const auto scene = MakeScene(opts);
  for (const bool priors : {false, true}) {
    SCOPED_TRACE(priors ? "with focal priors (F+H+E)" : "no priors (F+H)");
    const TwoViewGeometry g = Verify(scene, priors);
    EXPECT_EQ(g.config, priors ? kCalibrated : kUncalibrated);
    EXPECT_GT(InlierRecall(scene, g).first, 0.95);
  }
}

}  // namespace
}  // namespace cashash
