#include "cashash/geometry/fundamental_matrix.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "cashash/geometry/point_pairs.h"
#include "cashash/geometry/ransac.h"
#include "synthetic_two_view.h"

namespace cashash {
namespace {

using testing_support::MakeScene;
using testing_support::SceneOptions;

// Largest Sampson error (pixels) of the true inliers under F.
double MaxInlierError(const testing_support::SyntheticScene& scene, const PointPairs& pixels,
                      const Eigen::Matrix3d& F) {
  double f[9];
  RowMajor(F, f);
  double worst = 0;
  for (size_t i = 0; i < pixels.size(); ++i) {
    if (!scene.is_inlier[i]) continue;
    worst = std::max(worst, std::sqrt(SampsonSquaredError(f, pixels.x1[i], pixels.y1[i],
                                                          pixels.x2[i], pixels.y2[i])));
  }
  return worst;
}

TEST(FundamentalMatrix, SevenPointHasExactSolution) {
  SceneOptions opts;
  opts.num_inliers = 50;
  opts.outlier_ratio = 0;
  opts.noise_px = 0;
  const auto scene = MakeScene(opts);
  const PointPairs pixels = scene.Pairs();
  PointPairs normalized;
  const PairNormalization norm = NormalizePointPairs(pixels, &normalized);
  const int sample[7] = {0, 5, 11, 17, 23, 31, 42};
  Eigen::Matrix3d models[3];
  const int num = FundamentalSevenPoint(normalized, sample, models);
  ASSERT_GE(num, 1);
  double best = 1e9;
  for (int m = 0; m < num; ++m) {
    const Eigen::Matrix3d F = norm.T2.transpose() * models[m] * norm.T1;
    best = std::min(best, MaxInlierError(scene, pixels, F));
    EXPECT_NEAR(models[m].determinant(), 0.0, 1e-9);
  }
  // The correct root explains all 50 noiseless points, not just the 7.
  EXPECT_LT(best, 1e-6);
}

TEST(FundamentalMatrix, EightPointRecoversTrueF) {
  SceneOptions opts;
  opts.num_inliers = 200;
  opts.outlier_ratio = 0;
  opts.noise_px = 0;
  const auto scene = MakeScene(opts);
  const PointPairs pixels = scene.Pairs();
  PointPairs normalized;
  const PairNormalization norm = NormalizePointPairs(pixels, &normalized);
  std::vector<int> all(pixels.size());
  for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  Eigen::Matrix3d Fn;
  ASSERT_TRUE(FundamentalEightPoint(normalized, all, &Fn));
  Eigen::Matrix3d F = norm.T2.transpose() * Fn * norm.T1;
  F /= F.norm();
  Eigen::Matrix3d F_true = scene.TrueF();
  F_true /= F_true.norm();
  if (F.cwiseProduct(F_true).sum() < 0) F = -F;
  EXPECT_LT((F - F_true).norm(), 1e-6);
}

TEST(FundamentalMatrix, LoRansacRejectsOutliers) {
  SceneOptions opts;
  opts.num_inliers = 700;
  opts.outlier_ratio = 0.3;
  const auto scene = MakeScene(opts);
  const PointPairs pixels = scene.Pairs();
  PointPairs normalized;
  const PairNormalization norm = NormalizePointPairs(pixels, &normalized);
  RansacOptions ransac;
  ransac.max_error = 4.0 * norm.scale;
  ransac.seed = 42;
  const auto report = LoRansac(FundamentalEstimator(normalized), ransac);
  ASSERT_TRUE(report.success);
  const Eigen::Matrix3d F = norm.T2.transpose() * report.model * norm.T1;
  EXPECT_LT(MaxInlierError(scene, pixels, F), 4.0);

  int true_found = 0, outliers_kept = 0, num_true = 0, num_outliers = 0;
  for (size_t i = 0; i < pixels.size(); ++i) {
    num_true += scene.is_inlier[i];
    num_outliers += !scene.is_inlier[i];
    if (report.inlier_mask[i]) (scene.is_inlier[i] ? true_found : outliers_kept)++;
  }
  EXPECT_GT(true_found, 0.95 * num_true);
  EXPECT_LT(outliers_kept, 0.05 * num_outliers);
  EXPECT_EQ(report.support.num_inliers, true_found + outliers_kept);
  // 70% inliers with 7-point samples: COLMAP's rule asks for a few hundred.
  EXPECT_GE(report.num_trials, 100);
  EXPECT_LT(report.num_trials, 1000);
}

TEST(FundamentalMatrix, SameSeedSameResult) {
  const auto scene = MakeScene(SceneOptions());
  PointPairs normalized;
  const PairNormalization norm = NormalizePointPairs(scene.Pairs(), &normalized);
  RansacOptions ransac;
  ransac.max_error = 4.0 * norm.scale;
  ransac.seed = 123;
  const auto a = LoRansac(FundamentalEstimator(normalized), ransac);
  const auto b = LoRansac(FundamentalEstimator(normalized), ransac);
  EXPECT_EQ(a.inlier_mask, b.inlier_mask);
  EXPECT_EQ(a.num_trials, b.num_trials);
  EXPECT_EQ(a.model, b.model);
}

TEST(Ransac, TrialCountsFollowColmap) {
  // 50% inliers, 7-point samples, confidence 0.999, multiplier 3.
  EXPECT_EQ(RansacRequiredTrials(500, 1000, 0.999, 3.0, 7), 2643);
  // All inliers: one trial suffices.
  EXPECT_EQ(RansacRequiredTrials(1000, 1000, 0.999, 3.0, 7), 1);
  RansacOptions options;
  EXPECT_EQ(RansacMaxTrials(options, 7), 10000);  // min_inlier_ratio 0.25 asks more
  EXPECT_EQ(RansacMaxTrials(options, 4), 5295);  // ...but not 4-point samples
}

}  // namespace
}  // namespace cashash
