// Homography (x2 ~ H x1): 4-point minimal solver, least-squares DLT refit,
// squared transfer error, and the RANSAC estimator (COLMAP's H LO-RANSAC).
#pragma once

#include <vector>

#include <Eigen/Core>

#include "cashash/geometry/fundamental_matrix.h"
#include "cashash/geometry/point_pairs.h"
#include "cashash/geometry/ransac.h"

namespace cashash {

// H through the 4 pairs `idx`; false when three of either image's points are
// (nearly) collinear.
bool HomographyFourPoint(const PointPairs& pairs, const int* idx, Eigen::Matrix3d* model);

// Least-squares DLT through >= 4 pairs (normalised coordinates).
bool HomographyDlt(const PointPairs& pairs, const std::vector<int>& idx, Eigen::Matrix3d* model);

// Squared distance between x2 and H x1 (h: row-major entries).
template <typename T>
inline T HomographyTransferSquaredError(const T* h, T x1, T y1, T x2, T y2) {
  const T w = h[6] * x1 + h[7] * y1 + h[8];
  const T inv_w = T(1) / w;
  const T du = (h[0] * x1 + h[1] * y1 + h[2]) * inv_w - x2;
  const T dv = (h[3] * x1 + h[4] * y1 + h[5]) * inv_w - y2;
  return du * du + dv * dv;
}

class HomographyEstimator {
 public:
  using Model = Eigen::Matrix3d;
  static constexpr int kSampleSize = 4;
  static constexpr int kMaxModels = 1;
  static constexpr int kMinLocalSize = 4;

  explicit HomographyEstimator(const PointPairs& pairs) : pairs_(pairs) {}
  size_t NumData() const { return pairs_.size(); }

  int MinimalSolve(const int* sample, Model* models) const {
    return HomographyFourPoint(pairs_, sample, models) ? 1 : 0;
  }
  int LocalSolve(const std::vector<int>& inliers, Model* models) const {
    return HomographyDlt(pairs_, inliers, models) ? 1 : 0;
  }
  RansacSupport Score(const Model& model, double max_residual, int must_reach) const {
    float h[9];
    RowMajor(model, h);
    const float *x1 = pairs_.fx1.data(), *y1 = pairs_.fy1.data();
    const float *x2 = pairs_.fx2.data(), *y2 = pairs_.fy2.data();
    return ScoreResiduals(pairs_.size(), max_residual, must_reach, [&](size_t i) {
      return HomographyTransferSquaredError(h, x1[i], y1[i], x2[i], y2[i]);
    });
  }
  bool RejectedBySprt(const Model& model, double max_residual, const SprtTest& t, int start, int step) const {
    float h[9];
    RowMajor(model, h);
    return SprtRejectsResiduals(pairs_.size(), max_residual, t, start, step, [&](size_t i) { return Residual(h, i); });
  }
  void Inliers(const Model& model, double max_residual, std::vector<int>* out) const {
    float h[9];
    RowMajor(model, h);
    CollectInliers(pairs_.size(), max_residual, [&](size_t i) { return Residual(h, i); }, out);
  }
  void InlierMask(const Model& model, double max_residual, std::vector<char>* out) const {
    float h[9];
    RowMajor(model, h);
    CollectInlierMask(pairs_.size(), max_residual, [&](size_t i) { return Residual(h, i); }, out);
  }

 private:
  float Residual(const float* h, size_t i) const {
    return HomographyTransferSquaredError(h, pairs_.fx1[i], pairs_.fy1[i], pairs_.fx2[i],
                                          pairs_.fy2[i]);
  }

  const PointPairs& pairs_;
};

}  // namespace cashash
