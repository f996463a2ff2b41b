#include "cashash/geometry/essential_matrix.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "cashash/geometry/camera_models.h"
#include "cashash/geometry/point_pairs.h"
#include "cashash/geometry/ransac.h"
#include "synthetic_two_view.h"

namespace cashash {
namespace {

using testing_support::MakeScene;
using testing_support::SceneOptions;
using testing_support::SyntheticScene;

PointPairs NormalizedPairs(const SyntheticScene& scene) {
  const Camera camera = scene.MakeCamera(true);
  const PointPairs pixels = scene.Pairs();
  PointPairs world;
  world.resize(pixels.size());
  for (size_t i = 0; i < pixels.size(); ++i) {
    double u1, v1, u2, v2;
    CameraImageToWorld(camera, pixels.x1[i], pixels.y1[i], &u1, &v1);
    CameraImageToWorld(camera, pixels.x2[i], pixels.y2[i], &u2, &v2);
    world.Set(i, u1, v1, u2, v2);
  }
  return world;
}

// Distance between E and the true E, up to scale and sign.
double DistanceToTruth(const SyntheticScene& scene, Eigen::Matrix3d E) {
  Eigen::Matrix3d truth = scene.TrueE();
  truth /= truth.norm();
  E /= E.norm();
  return std::min((E - truth).norm(), (E + truth).norm());
}

TEST(EssentialMatrix, FivePointFindsTrueSolution) {
  SceneOptions opts;
  opts.num_inliers = 30;
  opts.outlier_ratio = 0;
  opts.noise_px = 0;
  for (unsigned seed = 1; seed <= 20; ++seed) {
    opts.seed = seed;
    const auto scene = MakeScene(opts);
    const PointPairs world = NormalizedPairs(scene);
    const int sample[5] = {0, 6, 12, 18, 24};
    Eigen::Matrix3d models[10];
    const int num = EssentialFivePoint(world, sample, 5, models);
    ASSERT_GE(num, 1);
    double best = 1e9;
    for (int m = 0; m < num; ++m) {
      best = std::min(best, DistanceToTruth(scene, models[m]));
      // Every solution is an essential matrix: singular values (s, s, 0).
      const Eigen::Vector3d s = Eigen::JacobiSVD<Eigen::Matrix3d>(models[m]).singularValues();
      EXPECT_NEAR(s(0), s(1), 1e-6 * s(0));
      EXPECT_NEAR(s(2), 0.0, 1e-6 * s(0));
    }
    EXPECT_LT(best, 1e-6) << "seed " << seed;
  }
}

TEST(EssentialMatrix, LeastSquaresOnManyPoints) {
  SceneOptions opts;
  opts.num_inliers = 100;
  opts.outlier_ratio = 0;
  opts.noise_px = 0;
  const auto scene = MakeScene(opts);
  const PointPairs world = NormalizedPairs(scene);
  std::vector<int> all(world.size());
  for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  Eigen::Matrix3d models[10];
  const int num = EssentialFivePoint(world, all.data(), static_cast<int>(all.size()), models);
  ASSERT_GE(num, 1);
  double best = 1e9;
  for (int m = 0; m < num; ++m) best = std::min(best, DistanceToTruth(scene, models[m]));
  EXPECT_LT(best, 1e-6);
}

TEST(EssentialMatrix, LoRansacRejectsOutliers) {
  const auto scene = MakeScene(SceneOptions());
  const PointPairs world = NormalizedPairs(scene);
  RansacOptions ransac;
  ransac.max_error = 4.0 / 1000.0;  // 4 px at f = 1000
  ransac.seed = 9;
  const auto report = LoRansac(EssentialEstimator(world), ransac);
  ASSERT_TRUE(report.success);
  EXPECT_LT(DistanceToTruth(scene, report.model), 0.02);
  int true_found = 0, outliers_kept = 0, num_true = 0, num_outliers = 0;
  for (size_t i = 0; i < world.size(); ++i) {
    num_true += scene.is_inlier[i];
    num_outliers += !scene.is_inlier[i];
    if (report.inlier_mask[i]) (scene.is_inlier[i] ? true_found : outliers_kept)++;
  }
  EXPECT_GT(true_found, 0.95 * num_true);
  EXPECT_LT(outliers_kept, 0.05 * num_outliers);
  const auto again = LoRansac(EssentialEstimator(world), ransac);
  EXPECT_EQ(again.inlier_mask, report.inlier_mask);
}

}  // namespace
}  // namespace cashash
