// The homography on the GPU, the twin of
// src/cashash/geometry/homography_matrix.cc: the transfer residual (float,
// the CPU path's formula), the 4-point minimal solver, the DLT rows of the
// local refit, and the model the RANSAC kernel (ransac.cu) runs.
#pragma once

#include "cashash_cuda/geometry/ransac_numerics.cuh"

namespace cashash {
namespace cuda {
namespace ransac {

__device__ inline float TransferSquared(const float* h, float4 p) {
  const float w = h[6] * p.x + h[7] * p.y + h[8];
  const float inv_w = 1.0f / w;
  const float du = (h[0] * p.x + h[1] * p.y + h[2]) * inv_w - p.z;
  const float dv = (h[3] * p.x + h[4] * p.y + h[5]) * inv_w - p.w;
  return du * du + dv * dv;
}

// The projective map sending the basis to p0, p1, p2 and (1,1,1) to p3
// (homogeneous points, row-major result); false when three are collinear.
__device__ inline bool BasisToPoints(const double (*p)[3], double* M) {
  double A[9] = {p[0][0], p[1][0], p[2][0], p[0][1], p[1][1], p[2][1], p[0][2], p[1][2], p[2][2]};
  if (fabs(Det3(A)) < 1e-10) return false;
  double inv[9];
  if (!Inverse3(A, inv)) return false;
  double l[3];
  for (int r = 0; r < 3; ++r) {
    l[r] = inv[3 * r] * p[3][0] + inv[3 * r + 1] * p[3][1] + inv[3 * r + 2] * p[3][2];
    if (fabs(l[r]) < 1e-10) return false;
  }
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) M[3 * r + c] = A[3 * r + c] * l[c];
  return true;
}

__device__ inline bool HomographyFourPoint(const float4* sample, double* h) {
  double p1[4][3], p2[4][3];
  for (int i = 0; i < 4; ++i) {
    p1[i][0] = sample[i].x;
    p1[i][1] = sample[i].y;
    p1[i][2] = 1;
    p2[i][0] = sample[i].z;
    p2[i][1] = sample[i].w;
    p2[i][2] = 1;
  }
  double M1[9], M2[9], M1_inv[9];
  if (!BasisToPoints(p1, M1) || !BasisToPoints(p2, M2) || !Inverse3(M1, M1_inv)) return false;
  Mul3(M2, M1_inv, h);
  return NormalizeModel(h);
}

// The two DLT rows of a correspondence.
__device__ inline void HomographyRows(float4 p, double* r1, double* r2) {
  const double x1 = p.x, y1 = p.y, x2 = p.z, y2 = p.w;
  r1[0] = -x1; r1[1] = -y1; r1[2] = -1; r1[3] = 0; r1[4] = 0; r1[5] = 0;
  r1[6] = x2 * x1; r1[7] = x2 * y1; r1[8] = x2;
  r2[0] = 0; r2[1] = 0; r2[2] = 0; r2[3] = -x1; r2[4] = -y1; r2[5] = -1;
  r2[6] = y2 * x1; r2[7] = y2 * y1; r2[8] = y2;
}

struct HomographyModel {
  static constexpr int kSampleSize = 4;
  static constexpr int kMaxModels = 1;
  static constexpr int kMinLocalSize = 4;
  __device__ static int Minimal(const float4* sample, double (*models)[9]) {
    return HomographyFourPoint(sample, models[0]) ? 1 : 0;
  }
  __device__ static float Residual(const float* m, float4 p) { return TransferSquared(m, p); }
  static constexpr bool kSampsonResidual = false;
  static constexpr bool kWarpLocalSolve = false;  // LocalSolve on one thread
  __device__ static void AddRows(float4 p, double* upper) {
    double r1[9], r2[9];
    HomographyRows(p, r1, r2);
    AddOuter(r1, upper);
    AddOuter(r2, upper);
  }
  __device__ static int LocalSolve(const double* upper, const double* start, double (*models)[9]) {
    if (!SmallestEigenvectorNear(upper, start, models[0])) {
      double full[81];
      ExpandNormalMatrix(upper, full);
      SmallestEigenvector<9>(full, models[0]);
    }
    return NormalizeModel(models[0]) ? 1 : 0;
  }
};

}  // namespace ransac
}  // namespace cuda
}  // namespace cashash
