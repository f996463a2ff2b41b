// The epipolar band of guided matching (Ga-CasHash, stage 2): a candidate
// of a query is kept only if it lies within max_distance pixels of the
// query's epipolar line. Header-only and usable from CUDA device code, so
// that the CPU cascade and the GPU select kernel apply the same test with the
// same arithmetic (double; keypoints are stored as float pixels).
//
// Convention: F is row-major with x2^T F x1 = 0 for pixel positions x1 of the
// pair's first image and x2 of its second image (TwoViewGeometry::F). The
// line of a first-image query x1 in the second image is F x1; the line of a
// second-image query x2 (the reverse query of cross-checking) in the first
// image is F^T x2. The distance of a point (x, y) to a line (a, b, c) is
// |a x + b y + c| / sqrt(a^2 + b^2) (the paper's equation for the candidate
// set C).
#pragma once

#include <cmath>

#include "cashash/base/host_device.h"

namespace cashash {

// A line a x + b y + c = 0 scaled so that a^2 + b^2 = 1 (|a x + b y + c| is the
// pixel distance). A query at the epipole has no line (a = b = 0): its band
// is the whole image (`everywhere`), as no constraint can be derived.
struct EpipolarLine {
  double a = 0, b = 0, c = 0;
  bool everywhere = true;

  CASHASH_HOST_DEVICE bool Contains(float x, float y, double max_distance) const {
    return everywhere || fabs(a * static_cast<double>(x) + b * static_cast<double>(y) + c) <= max_distance;
  }
};

CASHASH_HOST_DEVICE inline EpipolarLine NormalizedLine(double a, double b, double c) {
  EpipolarLine line;
  const double norm = sqrt(a * a + b * b);
  // Also rejects NaN (a non-finite F): then no constraint either.
  if (!(norm > 1e-300)) return line;
  line.a = a / norm;
  line.b = b / norm;
  line.c = c / norm;
  line.everywhere = false;
  return line;
}

// F x1: where matches of a first-image point lie in the second image.
CASHASH_HOST_DEVICE inline EpipolarLine LineInSecondImage(const double* F, float x1, float y1) {
  const double x = x1, y = y1;
  return NormalizedLine(F[0] * x + F[1] * y + F[2], F[3] * x + F[4] * y + F[5], F[6] * x + F[7] * y + F[8]);
}

// F^T x2: where matches of a second-image point lie in the first image.
CASHASH_HOST_DEVICE inline EpipolarLine LineInFirstImage(const double* F, float x2, float y2) {
  const double x = x2, y = y2;
  return NormalizedLine(F[0] * x + F[3] * y + F[6], F[1] * x + F[4] * y + F[7], F[2] * x + F[5] * y + F[8]);
}

}  // namespace cashash
