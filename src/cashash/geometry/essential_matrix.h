// Essential matrix (x2^T E x1 = 0 on normalised camera coordinates): the
// 5-point solver (Stewenius-style action matrix) and its RANSAC estimator.
// Residuals are squared Sampson errors in normalised coordinates.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "cashash/geometry/fundamental_matrix.h"
#include "cashash/geometry/point_pairs.h"

namespace cashash {

// Up to 10 essential matrices through the pairs `idx` (count >= 5). With more
// than 5 pairs, the 4-D null space is the least-squares one, as COLMAP's
// estimator does for its local refits.
int EssentialFivePoint(const PointPairs& pairs, const int* idx, int count, Eigen::Matrix3d* models);

// 5-point hypotheses and 5-point least-squares local refits.
class EssentialEstimator : public EpipolarScorer {
 public:
  using Model = Eigen::Matrix3d;
  static constexpr int kSampleSize = 5;
  static constexpr int kMaxModels = 10;
  static constexpr int kMinLocalSize = 5;

  using EpipolarScorer::EpipolarScorer;
  int MinimalSolve(const int* sample, Model* models) const {
    return EssentialFivePoint(pairs_, sample, kSampleSize, models);
  }
  int LocalSolve(const std::vector<int>& inliers, Model* models) const {
    return EssentialFivePoint(pairs_, inliers.data(), static_cast<int>(inliers.size()), models);
  }
};

}  // namespace cashash
