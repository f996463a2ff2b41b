// Cyclic Jacobi on a symmetric 9 x 9 matrix by one warp: the rotations in
// five_point::SymmetricJacobi's order, each rotation's row, column and
// eigenvector updates spread over 9 lanes. E's local refit (the 5-point
// solver on the least-squares null space of a pair's inliers) runs it; one
// thread alone took most of an E block's time while the other warps waited
// at the barrier after it (ncu: 60 % of the E kernel's stall samples on the
// instruction after that barrier).
#pragma once

#include <cuda_runtime.h>

#include "cashash/geometry/five_point_solver.h"

namespace cashash {
namespace cuda {

// `a` (destroyed: eigenvalues on its diagonal) and `v` (eigenvectors in its
// columns) are row-major in shared memory. Every lane of the warp calls it;
// every lane takes the same decisions (the sweep's norms and each rotation's
// angle are computed by all lanes from the same values).
__device__ inline void WarpSymmetricJacobi9(double* a, double* v) {
  constexpr int N = 9;
  const int lane = threadIdx.x % 32;
  for (int i = lane; i < N * N; i += 32) v[i] = (i % (N + 1) == 0) ? 1.0 : 0.0;
  __syncwarp();
  for (int sweep = 0; sweep < five_point::kJacobiMaxSweeps; ++sweep) {
    double off, diag;
    five_point::JacobiNorms<N>(a, &off, &diag);
    if (off <= five_point::kJacobiTolerance * diag || off == 0) break;
    for (int p = 0; p < N - 1; ++p) {
      for (int q = p + 1; q < N; ++q) {
        const double apq = a[p * N + q];
        if (apq == 0) continue;
        double c, s;
        five_point::JacobiRotation(a[p * N + p], a[q * N + q], apq, &c, &s);
        __syncwarp();  // every lane has read a[p][q], a[p][p] and a[q][q]
        if (lane < N) {
          five_point::RotatePair(&a[lane * N + p], &a[lane * N + q], c, s);  // columns p, q
          five_point::RotatePair(&v[lane * N + p], &v[lane * N + q], c, s);
        }
        __syncwarp();
        if (lane < N) five_point::RotatePair(&a[p * N + lane], &a[q * N + lane], c, s);  // rows p, q
        __syncwarp();
      }
    }
  }
}

}  // namespace cuda
}  // namespace cashash
