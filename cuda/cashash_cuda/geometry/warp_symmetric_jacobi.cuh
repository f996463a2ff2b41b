// Cyclic Jacobi on a symmetric 9 x 9 matrix by one warp: the rotations in
// five_point::SymmetricJacobi's order, each rotation's row, column and
// eigenvector updates spread over 9 lanes. E's local refit (the 5-point
// solver on the least-squares null space of a pair's inliers) runs it; one
// thread alone took most of an E block's time while the other warps waited
// at the barrier after it (ncu, device run 59: 60 % of the E kernel's stall
// samples on the instruction after that barrier).
#pragma once

#include <cuda_runtime.h>

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
  for (int sweep = 0; sweep < 50; ++sweep) {
    double off = 0, diag = 0;
    for (int p = 0; p < N; ++p) {
      diag += a[p * N + p] * a[p * N + p];
      for (int q = p + 1; q < N; ++q) off += a[p * N + q] * a[p * N + q];
    }
    if (off <= 1e-32 * diag || off == 0) break;
    for (int p = 0; p < N - 1; ++p) {
      for (int q = p + 1; q < N; ++q) {
        const double apq = a[p * N + q];
        if (apq == 0) continue;
        const double theta = (a[q * N + q] - a[p * N + p]) / (2 * apq);
        const double t = fabs(theta) > 1e150 ? 0.5 / theta
                                              : copysign(1.0, theta) / (fabs(theta) + sqrt(theta * theta + 1));
        const double c = 1 / sqrt(t * t + 1), s = t * c;
        __syncwarp();  // every lane has read a[p][q], a[p][p] and a[q][q]
        if (lane < N) {
          const int k = lane;
          const double akp = a[k * N + p], akq = a[k * N + q];
          a[k * N + p] = c * akp - s * akq;
          a[k * N + q] = s * akp + c * akq;
          const double vkp = v[k * N + p], vkq = v[k * N + q];
          v[k * N + p] = c * vkp - s * vkq;
          v[k * N + q] = s * vkp + c * vkq;
        }
        __syncwarp();
        if (lane < N) {
          const int k = lane;
          const double apk = a[p * N + k], aqk = a[q * N + k];
          a[p * N + k] = c * apk - s * aqk;
          a[q * N + k] = s * apk + c * aqk;
        }
        __syncwarp();
      }
    }
  }
}

}  // namespace cuda
}  // namespace cashash
