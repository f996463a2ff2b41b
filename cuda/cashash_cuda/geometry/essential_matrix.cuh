// The essential matrix on the GPU, the twin of
// src/cashash/geometry/essential_matrix.cc: 5-point hypotheses and refits
// (cashash/geometry/five_point_solver.h, shared with the CPU) and the model
// the RANSAC kernel (ransac.cu) runs.
#pragma once

#include "cashash_cuda/geometry/ransac_numerics.cuh"
#include "cashash/geometry/five_point_solver.h"
#include "cashash_cuda/geometry/fundamental_matrix.cuh"
#include "cashash_cuda/geometry/warp_five_point.cuh"
#include "cashash_cuda/geometry/warp_symmetric_jacobi.cuh"

namespace cashash {
namespace cuda {
namespace ransac {

// E on normalised camera coordinates (x2^T E x1 = 0): 5-point hypotheses,
// Sampson residuals as F, and the CPU path's local refit, the 5-point solver
// on the least-squares null space of all inliers (up to 10 models), which a
// warp runs (kWarpLocalSolve).
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
  static constexpr bool kWarpLocalSolve = true;  // WarpLocalSolve, not LocalSolve
  __device__ static void AddRows(float4 p, double* upper) {
    double row[9];
    EpipolarRow(p, row);
    AddOuter(row, upper);
  }
  // The least-squares null space of the normal matrix given by its 45
  // upper-triangle entries, as five_point::LeastSquaresNullSpace gives it,
  // with the eigen decomposition by the calling warp (WarpSymmetricJacobi9;
  // `a` and `v`: 81 doubles of shared memory each). Every lane calls it and
  // gets the same return value, false for non-finite input; lane 0 writes
  // the basis.
  __device__ static bool WarpLocalBasis(const double* upper, double* a, double* v, double (*basis)[9]) {
    const int lane = threadIdx.x % 32;
    bool finite = true;
    for (int i = lane; i < 81; i += 32) {
      a[i] = upper[five_point::NormalMatrixUpperIndex(i / 9, i % 9)];
      finite = finite && isfinite(a[i]);
    }
    finite = __all_sync(0xffffffffu, finite);
    __syncwarp();
    if (!finite) return false;
    WarpSymmetricJacobi9(a, v);
    if (lane == 0) five_point::NullSpaceFromEigen(a, v, basis);
    return true;
  }
  // The CPU path's local refit, the 5-point solver on that basis (up to 10
  // models, in `models`, shared memory): called by a whole warp, the count
  // on every lane.
  __device__ static int WarpLocalSolve(const double* upper, double* a, double* v, WarpFivePointScratch& scratch,
                                       double (*models)[9]) {
    if (!WarpLocalBasis(upper, a, v, scratch.basis)) return 0;
    return WarpSolveFromBasis(scratch, models);  // lane 0 wrote the basis it starts from
  }
};

}  // namespace ransac
}  // namespace cuda
}  // namespace cashash
