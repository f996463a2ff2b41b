// 2-D translation x2 = x1 + t, the model COLMAP fits to border matches to
// recognise watermarks and time stamps burnt into both images.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "cashash/geometry/point_pairs.h"
#include "cashash/geometry/ransac.h"

namespace cashash {

class TranslationEstimator {
 public:
  using Model = Eigen::Vector2d;
  static constexpr int kSampleSize = 1;
  static constexpr int kMaxModels = 1;
  static constexpr int kMinLocalSize = 1;

  explicit TranslationEstimator(const PointPairs& pairs) : pairs_(pairs) {}
  size_t NumData() const { return pairs_.size(); }

  int MinimalSolve(const int* sample, Model* models) const {
    const int k = sample[0];
    models[0] = Model(pairs_.x2[k] - pairs_.x1[k], pairs_.y2[k] - pairs_.y1[k]);
    return 1;
  }
  // Least squares: the mean displacement of the inliers.
  int LocalSolve(const std::vector<int>& inliers, Model* models) const {
    if (inliers.empty()) return 0;
    Model sum = Model::Zero();
    for (const int k : inliers) sum += Model(pairs_.x2[k] - pairs_.x1[k], pairs_.y2[k] - pairs_.y1[k]);
    models[0] = sum / static_cast<double>(inliers.size());
    return 1;
  }
  RansacSupport Score(const Model& t, double max_residual, int must_reach) const {
    return ScoreResiduals(pairs_.size(), max_residual, must_reach,
                          [&](size_t i) { return Residual(t, i); });
  }
  bool RejectedBySprt(const Model& t, double max_residual, const SprtTest& test, int start, int step) const {
    return SprtRejectsResiduals(pairs_.size(), max_residual, test, start, step,
                                [&](size_t i) { return Residual(t, i); });
  }
  void Inliers(const Model& t, double max_residual, std::vector<int>* out) const {
    CollectInliers(pairs_.size(), max_residual, [&](size_t i) { return Residual(t, i); }, out);
  }
  void InlierMask(const Model& t, double max_residual, std::vector<char>* out) const {
    CollectInlierMask(pairs_.size(), max_residual, [&](size_t i) { return Residual(t, i); }, out);
  }

 private:
  float Residual(const Model& t, size_t i) const {
    const float dx = pairs_.fx1[i] + static_cast<float>(t.x()) - pairs_.fx2[i];
    const float dy = pairs_.fy1[i] + static_cast<float>(t.y()) - pairs_.fy2[i];
    return dx * dx + dy * dy;
  }

  const PointPairs& pairs_;
};

}  // namespace cashash
