// Marks functions written once for the host and, under nvcc, the device
// (the 5-point solver, the epipolar band, the epipolar system's rows).
#pragma once

#if defined(__CUDACC__)
#define CASHASH_HOST_DEVICE __host__ __device__
#else
#define CASHASH_HOST_DEVICE
#endif

namespace cashash {

// Coefficients of x2^T M x1 in the row-major entries of M: one row of the
// linear epipolar system shared by the F and E solvers of both backends.
CASHASH_HOST_DEVICE inline void EpipolarCoefficients(double x1, double y1, double x2, double y2, double* row) {
  row[0] = x2 * x1;
  row[1] = x2 * y1;
  row[2] = x2;
  row[3] = y2 * x1;
  row[4] = y2 * y1;
  row[5] = y2;
  row[6] = x1;
  row[7] = y1;
  row[8] = 1.0;
}

}  // namespace cashash
