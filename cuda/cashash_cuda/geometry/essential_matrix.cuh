// The essential matrix on the GPU, the twin of
// src/cashash/geometry/essential_matrix.cc: 5-point hypotheses and refits
// (cashash/geometry/five_point_solver.h, shared with the CPU) and the model
// the RANSAC kernel (ransac.cu) runs.
#pragma once

#include "cashash_cuda/geometry/ransac_numerics.cuh"
#include "cashash/geometry/five_point_solver.h"
#include "cashash_cuda/geometry/fundamental_matrix.cuh"

namespace cashash {
namespace cuda {
namespace ransac {

// E on normalised camera coordinates (x2^T E x1 = 0): 5-point hypotheses,
// Sampson residuals as F, and the CPU path's local refit, the 5-point solver
// on the least-squares null space of all inliers (up to 10 models).
struct EssentialModel {
  static constexpr int kSampleSize = 5;
  static constexpr int kMaxModels = five_point::kMaxSolutions;
  static constexpr int kMinLocalSize = 5;
  __device__ static int Minimal(const float4* sample, double (*models)[9]) {
    double pairs[20];
    for (int k = 0; k < 5; ++k) {
      pairs[4 * k] = sample[k].x;
      pairs[4 * k + 1] = sample[k].y;
      pairs[4 * k + 2] = sample[k].z;
      pairs[4 * k + 3] = sample[k].w;
    }
    return five_point::EssentialFromFivePoints(pairs, models);
  }
  __device__ static float Residual(const float* m, float4 p) { return SampsonSquared(m, p); }
  static constexpr bool kSampsonResidual = true;  // Residual = SampsonParts' num2 / den
  static constexpr bool kLocalNullSpace = true;  // LocalSolve = LeastSquaresNullSpace + SolveFromBasis (ransac.cu splits it)
  __device__ static void AddRows(float4 p, double* upper) {
    double row[9];
    EpipolarRow(p, row);
    AddOuter(row, upper);
  }
  __device__ static int LocalSolve(const double* upper, const double* start, double (*models)[9]) {
    double basis[4][9];
    if (!five_point::LeastSquaresNullSpace(upper, basis)) return 0;
    return five_point::SolveFromBasis(basis, models);
  }
};

}  // namespace ransac
}  // namespace cuda
}  // namespace cashash
