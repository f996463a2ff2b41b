#include "cashash/geometry/homography_matrix.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "cashash/geometry/point_pairs.h"
#include "cashash/geometry/ransac.h"
#include "synthetic_two_view.h"

namespace cashash {
namespace {

using testing_support::MakeScene;
using testing_support::SceneOptions;

double MaxInlierTransferError(const testing_support::SyntheticScene& scene,
                              const PointPairs& pixels, const Eigen::Matrix3d& H) {
  double h[9];
  RowMajor(H, h);
  double worst = 0;
  for (size_t i = 0; i < pixels.size(); ++i) {
    if (!scene.is_inlier[i]) continue;
    worst = std::max(worst, std::sqrt(HomographyTransferSquaredError(
                                h, pixels.x1[i], pixels.y1[i], pixels.x2[i], pixels.y2[i])));
  }
  return worst;
}

SceneOptions PlanarScene(double outlier_ratio, double noise) {
  SceneOptions opts;
  opts.planar = true;
  opts.outlier_ratio = outlier_ratio;
  opts.noise_px = noise;
  return opts;
}

TEST(HomographyMatrix, FourPointIsExactOnPlane) {
  SceneOptions opts = PlanarScene(0, 0);
  opts.num_inliers = 40;
  const auto scene = MakeScene(opts);
  const PointPairs pixels = scene.Pairs();
  PointPairs normalized;
  const PairNormalization norm = NormalizePointPairs(pixels, &normalized);
  const int sample[4] = {1, 9, 20, 33};
  Eigen::Matrix3d Hn;
  ASSERT_TRUE(HomographyFourPoint(normalized, sample, &Hn));
  const Eigen::Matrix3d H = norm.T2.inverse() * Hn * norm.T1;
  EXPECT_LT(MaxInlierTransferError(scene, pixels, H), 1e-6);
}

TEST(HomographyMatrix, FourPointRejectsCollinear) {
  PointPairs p;
  p.resize(4);
  p.Set(0, 0, 0, 1, 1);
  p.Set(1, 1, 1, 2, 3);
  p.Set(2, 2, 2, 0, 5);
  p.Set(3, 0, 1, 4, 1);
  const int sample[4] = {0, 1, 2, 3};
  Eigen::Matrix3d H;
  EXPECT_FALSE(HomographyFourPoint(p, sample, &H));
}

TEST(HomographyMatrix, DltMatchesFourPointOnNoiselessPlane) {
  SceneOptions opts = PlanarScene(0, 0);
  opts.num_inliers = 100;
  const auto scene = MakeScene(opts);
  const PointPairs pixels = scene.Pairs();
  PointPairs normalized;
  const PairNormalization norm = NormalizePointPairs(pixels, &normalized);
  std::vector<int> all(pixels.size());
  for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  Eigen::Matrix3d Hn;
  ASSERT_TRUE(HomographyDlt(normalized, all, &Hn));
  EXPECT_LT(MaxInlierTransferError(scene, pixels, norm.T2.inverse() * Hn * norm.T1), 1e-6);
}

TEST(HomographyMatrix, LoRansacRejectsOutliers) {
  const auto scene = MakeScene(PlanarScene(0.3, 0.3));
  const PointPairs pixels = scene.Pairs();
  PointPairs normalized;
  const PairNormalization norm = NormalizePointPairs(pixels, &normalized);
  RansacOptions ransac;
  ransac.max_error = 4.0 * norm.scale;
  ransac.seed = 5;
  const auto report = LoRansac(HomographyEstimator(normalized), ransac);
  ASSERT_TRUE(report.success);
  EXPECT_LT(MaxInlierTransferError(scene, pixels, norm.T2.inverse() * report.model * norm.T1),
            4.0);
  int true_found = 0, outliers_kept = 0, num_true = 0, num_outliers = 0;
  for (size_t i = 0; i < pixels.size(); ++i) {
    num_true += scene.is_inlier[i];
    num_outliers += !scene.is_inlier[i];
    if (report.inlier_mask[i]) (scene.is_inlier[i] ? true_found : outliers_kept)++;
  }
  EXPECT_GT(true_found, 0.95 * num_true);
  EXPECT_LT(outliers_kept, 0.02 * num_outliers);

  const auto again = LoRansac(HomographyEstimator(normalized), ransac);
  EXPECT_EQ(again.inlier_mask, report.inlier_mask);
  EXPECT_EQ(again.model, report.model);
}

TEST(HomographyMatrix, GeneralSceneHasFewHomographyInliers) {
  SceneOptions opts;
  opts.outlier_ratio = 0;
  const auto scene = MakeScene(opts);
  PointPairs normalized;
  const PairNormalization norm = NormalizePointPairs(scene.Pairs(), &normalized);
  RansacOptions ransac;
  ransac.max_error = 4.0 * norm.scale;
  const auto report = LoRansac(HomographyEstimator(normalized), ransac);
  // Depths 4..10 m with a 1 m baseline: no plane explains most points.
  EXPECT_LT(report.support.num_inliers, 0.8 * scene.matches.size());
}

}  // namespace
}  // namespace cashash
