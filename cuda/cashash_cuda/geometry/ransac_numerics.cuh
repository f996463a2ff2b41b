// What the GPU RANSAC's models share, per thread and in double: the
// counter-based sampler, COLMAP's trial count, small dense linear algebra
// (3 x 3 inverse, a Jacobi eigen solver for the least-squares refits) and
// polynomial roots. The models themselves are in fundamental_matrix.cuh,
// homography_matrix.cuh and essential_matrix.cuh, beside their CPU twins'
// names in src/cashash/geometry/.
#pragma once

#include <cstdint>

#include "cashash/base/host_device.h"
#include "cashash/geometry/five_point_solver.h"

namespace cashash {
namespace cuda {
namespace ransac {

// --- Random samples --------------------------------------------------------

// SplitMix64, as the CPU sampler; every trial gets its own stream derived
// from the pair's seed and the trial index, so results do not depend on
// which thread runs which trial.
struct DeviceSplitMix64 {
  uint64_t state;
  __device__ uint64_t Next() {
    uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  __device__ uint32_t Below(uint32_t n) { return static_cast<uint32_t>(__umul64hi(Next(), n)); }
};

__device__ inline DeviceSplitMix64 TrialRng(uint64_t seed, uint32_t trial) {
  DeviceSplitMix64 rng{seed ^ ((static_cast<uint64_t>(trial) + 1) * 0xD1B54A32D192ED03ull)};
  rng.Next();
  return rng;
}

template <int K>
__device__ inline void SampleDistinct(DeviceSplitMix64& rng, uint32_t n, int* out) {
  for (int i = 0; i < K; ++i) {
    for (;;) {
      const int candidate = static_cast<int>(rng.Below(n));
      bool taken = false;
      for (int j = 0; j < i; ++j) taken |= out[j] == candidate;
      if (!taken) {
        out[i] = candidate;
        break;
      }
    }
  }
}

// COLMAP's adaptive trial count (RansacRequiredTrials of ransac.h).
__device__ inline int RequiredTrials(int num_inliers, int num_samples, double confidence, double multiplier,
                                     int sample_size) {
  const double inlier_ratio = static_cast<double>(num_inliers) / static_cast<double>(num_samples);
  const double nom = 1.0 - confidence;
  if (nom <= 0) return 0x7fffffff;
  const double denom = 1.0 - pow(inlier_ratio, static_cast<double>(sample_size));
  if (denom <= 0) return 1;
  if (denom == 1.0) return 0x7fffffff;
  const double trials = ceil(log(nom) / log(denom) * multiplier);
  return trials >= 2147483647.0 ? 0x7fffffff : static_cast<int>(trials);
}

// --- Small dense linear algebra (double) -----------------------------------

__device__ inline double Det3(const double* m) {
  return m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
         m[2] * (m[3] * m[7] - m[4] * m[6]);
}

// Inverse of a row-major 3x3; false when singular.
__device__ inline bool Inverse3(const double* m, double* inv) {
  const double det = Det3(m);
  if (det == 0 || !isfinite(det)) return false;
  const double r = 1.0 / det;
  inv[0] = (m[4] * m[8] - m[5] * m[7]) * r;
  inv[1] = (m[2] * m[7] - m[1] * m[8]) * r;
  inv[2] = (m[1] * m[5] - m[2] * m[4]) * r;
  inv[3] = (m[5] * m[6] - m[3] * m[8]) * r;
  inv[4] = (m[0] * m[8] - m[2] * m[6]) * r;
  inv[5] = (m[2] * m[3] - m[0] * m[5]) * r;
  inv[6] = (m[3] * m[7] - m[4] * m[6]) * r;
  inv[7] = (m[1] * m[6] - m[0] * m[7]) * r;
  inv[8] = (m[0] * m[4] - m[1] * m[3]) * r;
  return true;
}

__device__ inline void Mul3(const double* a, const double* b, double* out) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out[3 * r + c] = a[3 * r] * b[c] + a[3 * r + 1] * b[3 + c] + a[3 * r + 2] * b[6 + c];
}

// Scales to unit Frobenius norm; false when zero or not finite.
__device__ inline bool NormalizeModel(double* m) {
  double s = 0;
  for (int i = 0; i < 9; ++i) s += m[i] * m[i];
  const double norm = sqrt(s);
  if (!(norm > 0) || !isfinite(norm)) return false;
  for (int i = 0; i < 9; ++i) m[i] /= norm;
  return true;
}

// Cyclic Jacobi on a symmetric row-major N x N matrix `a` (destroyed);
// writes the unit eigenvector of the smallest eigenvalue to `out`.
template <int N>
__device__ void SmallestEigenvector(double* a, double* out) {
  double v[N * N];
  five_point::SymmetricJacobi<N>(a, v, 40, 1e-30);
  int best = 0;
  for (int i = 1; i < N; ++i) {
    if (a[i * N + i] < a[best * N + best]) best = i;
  }
  for (int k = 0; k < N; ++k) out[k] = v[k * N + best];
}

// The unit eigenvector of the smallest eigenvalue of the symmetric positive
// semi-definite 9 x 9 matrix given by its 45 upper-triangle entries, by
// inverse iteration from `start` (the model being refined, which lies close
// to it): each step solves (A + shift I) x = x_prev by Cholesky. The ratio
// of the two smallest eigenvalues of a refit's normal matrix is tiny, so a
// few steps converge to what a full eigen decomposition gives, at a small
// fraction of a Jacobi sweep's cost on one thread. False when the
// factorisation breaks down (non-finite input).
__device__ inline bool SmallestEigenvectorNear(const double* upper, const double* start, double* out) {
  double L[45];  // lower-triangular Cholesky factor, packed by rows: L(i, j) at i (i + 1) / 2 + j
  double trace = 0;
  {
    int k = 0;
#pragma unroll
    for (int i = 0; i < 9; ++i) {
      trace += upper[k];
      k += 9 - i;
    }
  }
  const double shift = 1e-13 * trace + 1e-300;
#pragma unroll
  for (int i = 0; i < 9; ++i) {
#pragma unroll
    for (int j = 0; j <= i; ++j) {
      // A(i, j) from the upper-triangle packing (row j, column i, j <= i).
      const int upper_index = j * 9 - j * (j - 1) / 2 + (i - j);
      double sum = upper[upper_index] + (i == j ? shift : 0.0);
#pragma unroll
      for (int k = 0; k < j; ++k) sum -= L[i * (i + 1) / 2 + k] * L[j * (j + 1) / 2 + k];
      if (i == j) {
        if (!(sum > 0)) return false;
        L[i * (i + 1) / 2 + i] = sqrt(sum);
      } else {
        L[i * (i + 1) / 2 + j] = sum / L[j * (j + 1) / 2 + j];
      }
    }
  }
  double x[9];
#pragma unroll
  for (int i = 0; i < 9; ++i) x[i] = start[i];
  for (int iteration = 0; iteration < 4; ++iteration) {
    double y[9];
#pragma unroll
    for (int i = 0; i < 9; ++i) {  // L y = x
      double sum = x[i];
#pragma unroll
      for (int k = 0; k < i; ++k) sum -= L[i * (i + 1) / 2 + k] * y[k];
      y[i] = sum / L[i * (i + 1) / 2 + i];
    }
#pragma unroll
    for (int i = 8; i >= 0; --i) {  // L^T x = y
      double sum = y[i];
#pragma unroll
      for (int k = i + 1; k < 9; ++k) sum -= L[k * (k + 1) / 2 + i] * x[k];
      x[i] = sum / L[i * (i + 1) / 2 + i];
    }
    double norm = 0;
#pragma unroll
    for (int i = 0; i < 9; ++i) norm += x[i] * x[i];
    norm = sqrt(norm);
    if (!(norm > 0) || !isfinite(norm)) return false;
#pragma unroll
    for (int i = 0; i < 9; ++i) x[i] /= norm;
  }
#pragma unroll
  for (int i = 0; i < 9; ++i) out[i] = x[i];
  return true;
}

// Expands the 45 upper-triangle sums (row-major order over i <= j) of a
// normal matrix into the full 9 x 9.
__device__ inline void ExpandNormalMatrix(const double* upper, double* full) {
  int k = 0;
  for (int i = 0; i < 9; ++i)
    for (int j = i; j < 9; ++j) {
      full[i * 9 + j] = full[j * 9 + i] = upper[k++];
    }
}

__device__ inline void AddOuter(const double* row, double* upper) {
  int k = 0;
  for (int i = 0; i < 9; ++i)
    for (int j = i; j < 9; ++j) upper[k++] += row[i] * row[j];
}

// --- Real roots of a cubic (as polynomial_roots.cc) -------------------------

__device__ inline int QuadraticRoots(double a, double b, double c, double* roots) {
  if (a == 0) {
    if (b == 0) return 0;
    roots[0] = -c / b;
    return 1;
  }
  const double disc = b * b - 4 * a * c;
  if (disc < 0) return 0;
  const double q = -0.5 * (b + copysign(sqrt(disc), b));
  if (q == 0) {
    roots[0] = 0;
    return 1;
  }
  roots[0] = q / a;
  roots[1] = c / q;
  return 2;
}

__device__ inline int CubicRoots(double c3, double c2, double c1, double c0, double* roots) {
  const double scale = fabs(c2) + fabs(c1) + fabs(c0);
  if (fabs(c3) <= 1e-14 * scale) return QuadraticRoots(c2, c1, c0, roots);
  const double a = c2 / c3, b = c1 / c3, c = c0 / c3;
  const double a_third = a / 3.0;
  const double p = b - a * a_third;
  const double q = 2.0 * a_third * a_third * a_third - a_third * b + c;
  const double disc = 0.25 * q * q + p * p * p / 27.0;
  int n = 0;
  if (disc > 0) {
    const double s = sqrt(disc);
    roots[n++] = cbrt(-0.5 * q + s) + cbrt(-0.5 * q - s) - a_third;
  } else if (p == 0) {
    roots[n++] = -a_third;
  } else {
    const double r = sqrt(-p / 3.0);
    const double arg = fmax(-1.0, fmin(1.0, -0.5 * q / (r * r * r)));
    const double phi = acos(arg) / 3.0;
    for (int k = 0; k < 3; ++k) roots[n++] = 2.0 * r * cos(phi - 2.0 * 3.14159265358979323846 * k / 3.0) - a_third;
  }
  for (int i = 0; i < n; ++i) {  // two Newton steps polish the closed form
    double x = roots[i];
    for (int it = 0; it < 2; ++it) {
      const double f = ((x + a) * x + b) * x + c;
      const double df = (3 * x + 2 * a) * x + b;
      if (df == 0) break;
      x -= f / df;
    }
    roots[i] = x;
  }
  return n;
}

}  // namespace ransac
}  // namespace cuda
}  // namespace cashash
