// Fundamental matrix (x2^T F x1 = 0): 7-point minimal solver, least-squares
// 8-point refit, squared Sampson error, and the RANSAC estimator using them.
// The same estimator serves the essential matrix's residuals, since E is a
// fundamental matrix of normalised camera coordinates.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "cashash/geometry/point_pairs.h"
#include "cashash/geometry/ransac.h"

namespace cashash {

// Up to 3 rank-2 solutions through the 7 pairs `idx` of `pairs`. Points
// should be normalised (centroid 0, scale ~1) for good conditioning.
int FundamentalSevenPoint(const PointPairs& pairs, const int* idx, Eigen::Matrix3d* models);

// Least-squares rank-2 F through >= 8 pairs (normalised coordinates).
bool FundamentalEightPoint(const PointPairs& pairs, const std::vector<int>& idx,
                           Eigen::Matrix3d* model);

// Squared Sampson error of pair i under F (row-major entries f[9]).
template <typename T>
inline T SampsonSquaredError(const T* f, T x1, T y1, T x2, T y2) {
  const T a = f[0] * x1 + f[1] * y1 + f[2];
  const T b = f[3] * x1 + f[4] * y1 + f[5];
  const T c = f[6] * x1 + f[7] * y1 + f[8];
  const T d = f[0] * x2 + f[3] * y2 + f[6];
  const T e = f[1] * x2 + f[4] * y2 + f[7];
  const T num = x2 * a + y2 * b + c;
  return num * num / (a * a + b * b + d * d + e * e);
}

// Row-major copy of a 3x3 matrix, the layout the residual loops read.
template <typename T>
inline void RowMajor(const Eigen::Matrix3d& m, T* out) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out[3 * r + c] = static_cast<T>(m(r, c));
}

// Sampson-error scoring shared by the F and E estimators.
class EpipolarScorer {
 public:
  explicit EpipolarScorer(const PointPairs& pairs) : pairs_(pairs) {}
  size_t NumData() const { return pairs_.size(); }

  RansacSupport Score(const Eigen::Matrix3d& model, double max_residual, int must_reach) const {
    float f[9];
    RowMajor(model, f);
    const float *x1 = pairs_.fx1.data(), *y1 = pairs_.fy1.data();
    const float *x2 = pairs_.fx2.data(), *y2 = pairs_.fy2.data();
    return ScoreResiduals(pairs_.size(), max_residual, must_reach,
                          [&](size_t i) { return SampsonSquaredError(f, x1[i], y1[i], x2[i], y2[i]); });
  }
  bool RejectedBySprt(const Eigen::Matrix3d& model, double max_residual, const SprtTest& t, int start, int step) const {
    float f[9];
    RowMajor(model, f);
    return SprtRejectsResiduals(pairs_.size(), max_residual, t, start, step, [&](size_t i) { return Residual(f, i); });
  }
  void Inliers(const Eigen::Matrix3d& model, double max_residual, std::vector<int>* out) const {
    float f[9];
    RowMajor(model, f);
    CollectInliers(pairs_.size(), max_residual, [&](size_t i) { return Residual(f, i); }, out);
  }
  void InlierMask(const Eigen::Matrix3d& model, double max_residual, std::vector<char>* out) const {
    float f[9];
    RowMajor(model, f);
    CollectInlierMask(pairs_.size(), max_residual, [&](size_t i) { return Residual(f, i); }, out);
  }

 private:
  float Residual(const float* f, size_t i) const {
    return SampsonSquaredError(f, pairs_.fx1[i], pairs_.fy1[i], pairs_.fx2[i], pairs_.fy2[i]);
  }

 protected:
  const PointPairs& pairs_;
};

// 7-point hypotheses, normalised 8-point local refits (COLMAP's F LO-RANSAC).
class FundamentalEstimator : public EpipolarScorer {
 public:
  using Model = Eigen::Matrix3d;
  static constexpr int kSampleSize = 7;
  static constexpr int kMaxModels = 3;
  static constexpr int kMinLocalSize = 8;

  using EpipolarScorer::EpipolarScorer;
  int MinimalSolve(const int* sample, Model* models) const {
    return FundamentalSevenPoint(pairs_, sample, models);
  }
  int LocalSolve(const std::vector<int>& inliers, Model* models) const {
    return FundamentalEightPoint(pairs_, inliers, models) ? 1 : 0;
  }
};

}  // namespace cashash
