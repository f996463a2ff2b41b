// Corresponding 2-D points stored as four flat arrays (structure of arrays),
// so that scoring a model over all pairs is a straight vectorisable loop.
// Solvers read the double arrays; model scoring reads the float mirrors,
// which fit eight to an AVX register (the coordinates are normalised to unit
// scale or are pixels, where float resolves far below the 4 px threshold).
#pragma once

#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "cashash/base/host_device.h"

namespace cashash {

struct PointPairs {
  std::vector<double> x1, y1, x2, y2;
  std::vector<float> fx1, fy1, fx2, fy2;

  size_t size() const { return x1.size(); }
  void resize(size_t n) {
    x1.resize(n);
    y1.resize(n);
    x2.resize(n);
    y2.resize(n);
    fx1.resize(n);
    fy1.resize(n);
    fx2.resize(n);
    fy2.resize(n);
  }
  void Set(size_t i, double ax, double ay, double bx, double by) {
    x1[i] = ax;
    y1[i] = ay;
    x2[i] = bx;
    y2[i] = by;
    fx1[i] = static_cast<float>(ax);
    fy1[i] = static_cast<float>(ay);
    fx2[i] = static_cast<float>(bx);
    fy2[i] = static_cast<float>(by);
  }
};

// Coefficients of x2^T M x1 in the row-major entries of M for pair k: one
// row of the linear epipolar system shared by the F and E solvers.
inline void EpipolarRow(const PointPairs& pairs, size_t k, double* row) {
  EpipolarCoefficients(pairs.x1[k], pairs.y1[k], pairs.x2[k], pairs.y2[k], row);
}

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
