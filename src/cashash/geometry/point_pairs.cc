#include "cashash/geometry/point_pairs.h"

#include <cmath>

namespace cashash {

PairNormalization NormalizePointPairs(const PointPairs& pixels, PointPairs* normalized) {
  PairNormalization norm;
  const size_t n = pixels.size();
  normalized->resize(n);
  if (n == 0) return norm;
  double cx1 = 0, cy1 = 0, cx2 = 0, cy2 = 0;
  for (size_t i = 0; i < n; ++i) {
    cx1 += pixels.x1[i];
    cy1 += pixels.y1[i];
    cx2 += pixels.x2[i];
    cy2 += pixels.y2[i];
  }
  cx1 /= n;
  cy1 /= n;
  cx2 /= n;
  cy2 /= n;
  double dist = 0;
  for (size_t i = 0; i < n; ++i) {
    dist += std::hypot(pixels.x1[i] - cx1, pixels.y1[i] - cy1);
    dist += std::hypot(pixels.x2[i] - cx2, pixels.y2[i] - cy2);
  }
  dist /= 2.0 * n;
  const double s = dist > 0 ? std::sqrt(2.0) / dist : 1.0;
  for (size_t i = 0; i < n; ++i) {
    normalized->Set(i, s * (pixels.x1[i] - cx1), s * (pixels.y1[i] - cy1), s * (pixels.x2[i] - cx2),
                    s * (pixels.y2[i] - cy2));
  }
  norm.scale = s;
  norm.T1 << s, 0, -s * cx1, 0, s, -s * cy1, 0, 0, 1;
  norm.T2 << s, 0, -s * cx2, 0, s, -s * cy2, 0, 0, 1;
  return norm;
}

}  // namespace cashash
