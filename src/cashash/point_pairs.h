// Corresponding 2-D points stored as four flat arrays (structure of arrays),
// so that scoring a model over all pairs is a straight vectorisable loop.
#pragma once

#include <cstddef>
#include <vector>

#include <Eigen/Core>

namespace cashash {

struct PointPairs {
  std::vector<double> x1, y1, x2, y2;

  size_t size() const { return x1.size(); }
  void resize(size_t n) {
    x1.resize(n);
    y1.resize(n);
    x2.resize(n);
    y2.resize(n);
  }
  void Set(size_t i, double ax, double ay, double bx, double by) {
    x1[i] = ax;
    y1[i] = ay;
    x2[i] = bx;
    y2[i] = by;
  }
};

// Moves each image's points to their centroid and scales both images by the
// same factor (mean distance sqrt(2) over both). With one common scale s, the
// Sampson and transfer errors in normalised coordinates are exactly s times
// the pixel errors, so RANSAC can run entirely on the well-conditioned copy
// with a threshold of s * max_error.
struct PairNormalization {
  Eigen::Matrix3d T1 = Eigen::Matrix3d::Identity();  // normalised = T1 * pixel
  Eigen::Matrix3d T2 = Eigen::Matrix3d::Identity();
  double scale = 1.0;
};

PairNormalization NormalizePointPairs(const PointPairs& pixels, PointPairs* normalized);

}  // namespace cashash
