// The fundamental matrix on the GPU, the twin of
// src/cashash/geometry/fundamental_matrix.cc: the Sampson residual (float,
// the CPU path's formula), the 7-point minimal solver, the rank-2
// projection, and the model the RANSAC kernel (ransac.cu) runs.
#pragma once

#include "cashash_cuda/geometry/ransac_numerics.cuh"

namespace cashash {
namespace cuda {
namespace ransac {

// The squared Sampson error as its numerator and denominator, so that a
// scan can reject a point without dividing (ransac.cu, IsInlier); the
// residual is exactly num2 / den either way.
__device__ inline void SampsonParts(const float* f, float4 p, float* num2, float* den) {
  const float a = f[0] * p.x + f[1] * p.y + f[2];
  const float b = f[3] * p.x + f[4] * p.y + f[5];
  const float c = f[6] * p.x + f[7] * p.y + f[8];
  const float d = f[0] * p.z + f[3] * p.w + f[6];
  const float e = f[1] * p.z + f[4] * p.w + f[7];
  const float num = p.z * a + p.w * b + c;
  *num2 = num * num;
  *den = a * a + b * b + d * d + e * e;
}

__device__ inline float SampsonSquared(const float* f, float4 p) {
  float num2, den;
  SampsonParts(f, p, &num2, &den);
  return num2 / den;
}

// Coefficients of x2^T F x1 in the row-major entries of F, for a packed
// correspondence (x1, y1, x2, y2).
__device__ inline void EpipolarRow(float4 p, double* row) { EpipolarCoefficients(p.x, p.y, p.z, p.w, row); }

// Two vectors spanning the null space of the 7 x 9 system, by Gauss-Jordan
// elimination with full pivoting; false when the sample is degenerate
// (rank below 7).
__device__ inline bool SevenPointNullSpace(const float4* sample, double* n1, double* n2) {
  double A[7][9];
  for (int i = 0; i < 7; ++i) EpipolarRow(sample[i], A[i]);
  int col[9];
  for (int j = 0; j < 9; ++j) col[j] = j;
  double max_abs = 0;
  for (int i = 0; i < 7; ++i)
    for (int j = 0; j < 9; ++j) max_abs = fmax(max_abs, fabs(A[i][j]));
  for (int r = 0; r < 7; ++r) {
    int pr = r, pc = r;
    double best = -1;
    for (int i = r; i < 7; ++i)
      for (int j = r; j < 9; ++j) {
        const double v = fabs(A[i][col[j]]);
        if (v > best) {
          best = v;
          pr = i;
          pc = j;
        }
      }
    if (!(best > 1e-12 * max_abs)) return false;
    if (pr != r)
      for (int j = 0; j < 9; ++j) {
        const double t = A[r][j];
        A[r][j] = A[pr][j];
        A[pr][j] = t;
      }
    const int tc = col[r];
    col[r] = col[pc];
    col[pc] = tc;
    const int c = col[r];
    const double inv = 1.0 / A[r][c];
    for (int j = 0; j < 9; ++j) A[r][j] *= inv;
    for (int i = 0; i < 7; ++i) {
      if (i == r) continue;
      const double f = A[i][c];
      if (f == 0) continue;
      for (int j = 0; j < 9; ++j) A[i][j] -= f * A[r][j];
    }
  }
  // Pivot variables x[col[r]] = -A[r][free] for each free column set to 1.
  double* out[2] = {n1, n2};
  for (int f = 0; f < 2; ++f) {
    const int free_col = col[7 + f];
    for (int j = 0; j < 9; ++j) out[f][j] = 0;
    out[f][free_col] = 1;
    for (int r = 0; r < 7; ++r) out[f][col[r]] = -A[r][free_col];
  }
  return true;
}

// Up to 3 rank-2 F (unit norm) through 7 normalised correspondences.
__device__ inline int FundamentalSevenPoint(const float4* sample, double (*models)[9]) {
  double F1[9], F2[9];
  if (!SevenPointNullSpace(sample, F1, F2)) return 0;
  double G[9], P[9];
  for (int i = 0; i < 9; ++i) {
    G[i] = F1[i] - F2[i];
    P[i] = F2[i] - G[i];
  }
  // det(F2 + a G) = c0 + c1 a + c2 a^2 + c3 a^3, from a = 0, 1, -1 and det(G).
  const double c0 = Det3(F2), c3 = Det3(G), p1 = Det3(F1), pm1 = Det3(P);
  const double c2 = 0.5 * (p1 + pm1) - c0;
  const double c1 = 0.5 * (p1 - pm1) - c3;
  double roots[3];
  const int num_roots = CubicRoots(c3, c2, c1, c0, roots);
  int n = 0;
  for (int k = 0; k < num_roots; ++k) {
    for (int i = 0; i < 9; ++i) models[n][i] = F2[i] + roots[k] * G[i];
    if (NormalizeModel(models[n])) ++n;
  }
  return n;
}

// The closest rank-2 matrix: F (I - v v^T) with v the right singular vector
// of the smallest singular value (smallest eigenvector of F^T F).
__device__ inline bool ProjectRankTwo(double* f) {
  double FtF[9];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) FtF[3 * r + c] = f[r] * f[c] + f[3 + r] * f[3 + c] + f[6 + r] * f[6 + c];
  double v[3];
  SmallestEigenvector<3>(FtF, v);
  for (int r = 0; r < 3; ++r) {
    const double fv = f[3 * r] * v[0] + f[3 * r + 1] * v[1] + f[3 * r + 2] * v[2];
    for (int c = 0; c < 3; ++c) f[3 * r + c] -= fv * v[c];
  }
  return NormalizeModel(f);
}

struct FundamentalModel {
  static constexpr int kSampleSize = 7;
  static constexpr int kMaxModels = 3;
  static constexpr int kMinLocalSize = 8;
  __device__ static int Minimal(const float4* sample, double (*models)[9]) {
    return FundamentalSevenPoint(sample, models);
  }
  __device__ static float Residual(const float* m, float4 p) { return SampsonSquared(m, p); }
  static constexpr bool kSampsonResidual = true;  // Residual = SampsonParts' num2 / den
  static constexpr bool kWarpLocalSolve = false;  // LocalSolve on one thread
  __device__ static void AddRows(float4 p, double* upper) {
    double row[9];
    EpipolarRow(p, row);
    AddOuter(row, upper);
  }
  // Smallest eigenvector of the normal matrix by inverse iteration from the
  // model being refined (a full Jacobi decomposition where the factorisation
  // breaks down), projected to rank 2.
  __device__ static int LocalSolve(const double* upper, const double* start, double (*models)[9]) {
    if (!SmallestEigenvectorNear(upper, start, models[0])) {
      double full[81];
      ExpandNormalMatrix(upper, full);
      SmallestEigenvector<9>(full, models[0]);
    }
    return ProjectRankTwo(models[0]) ? 1 : 0;
  }
};

}  // namespace ransac
}  // namespace cuda
}  // namespace cashash
