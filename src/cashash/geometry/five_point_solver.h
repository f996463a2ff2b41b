// The 5-point essential-matrix solver in plain C++ that compiles both for
// the host and as CUDA device code (one thread per call, double precision,
// no allocation, no library): the GPU RANSAC runs it per hypothesis, and the
// CPU tests check the host instantiation against the Eigen solver of
// essential_matrix.cc (same solutions up to scale and sign).
//
// Nister's formulation: E = x E1 + y E2 + z E3 + E4 over a basis of the
// null space of the epipolar system (Householder QR of the 5 x 9 system for
// a minimal sample, the four smallest eigenvectors of the normal matrix for
// a least-squares refit, the smallest being E4 as on the CPU); the ten cubic
// constraints det(E) = 0 and 2 E E^T E - trace(E E^T) E = 0 as a 10 x 20
// matrix over the monomials of (x, y, z); Gauss-Jordan elimination of its
// left 10 x 10 block; the 3 x 3 matrix of polynomials in z left by three
// row differences, whose determinant is a degree-10 polynomial in z; its
// real roots isolated with a Sturm sequence and polished by safeguarded
// Newton steps (sturm_roots.h); x and y from the null vector of the 3 x 3
// matrix at each z. EliminateToDeterminant and ModelAtRoot are apart so that
// the GPU's local refit can find each root's model on its own lane.
#pragma once

#include <cmath>

#include "cashash/base/host_device.h"
#include "cashash/geometry/sturm_roots.h"

namespace cashash {
namespace five_point {

#if !defined(__CUDA_ARCH__)
// Host pass: the standard overloads (device code gets CUDA's own).
using std::copysign;
using std::fabs;
using std::fmax;
using std::isfinite;
using std::sqrt;
#endif

constexpr int kMaxSolutions = 10;

// Coefficients of x2^T E x1 in the row-major entries of E (host_device.h).
using ::cashash::EpipolarCoefficients;

// Orthonormal basis of the null space of the 5 x 9 system `rows`, as the
// last four columns of Q in the Householder QR of its 9 x 5 transpose (what
// the CPU solver takes). False when a column vanishes (not finite input).
CASHASH_HOST_DEVICE inline bool MinimalNullSpace(const double (*rows)[9], double (*basis)[9]) {
  double m[5][9];  // m[j] = column j of the 9 x 5 matrix = rows[j]
  double v[5][9];
  double beta[5];
  for (int j = 0; j < 5; ++j)
    for (int i = 0; i < 9; ++i) m[j][i] = rows[j][i];
  for (int k = 0; k < 5; ++k) {
    double norm2 = 0;
    for (int i = k; i < 9; ++i) norm2 += m[k][i] * m[k][i];
    const double norm = sqrt(norm2);
    if (!(norm > 0) || !isfinite(norm)) return false;
    const double alpha = m[k][k] > 0 ? -norm : norm;
    for (int i = 0; i < 9; ++i) v[k][i] = i < k ? 0.0 : m[k][i];
    v[k][k] -= alpha;
    double vtv = 0;
    for (int i = k; i < 9; ++i) vtv += v[k][i] * v[k][i];
    beta[k] = vtv > 0 ? 2.0 / vtv : 0.0;
    for (int j = k + 1; j < 5; ++j) {
      double d = 0;
      for (int i = k; i < 9; ++i) d += v[k][i] * m[j][i];
      d *= beta[k];
      for (int i = k; i < 9; ++i) m[j][i] -= d * v[k][i];
    }
  }
  for (int c = 0; c < 4; ++c) {
    double q[9];
    for (int i = 0; i < 9; ++i) q[i] = i == 5 + c ? 1.0 : 0.0;
    for (int k = 4; k >= 0; --k) {  // Q e = H0 H1 H2 H3 H4 e
      double d = 0;
      for (int i = k; i < 9; ++i) d += v[k][i] * q[i];
      d *= beta[k];
      for (int i = k; i < 9; ++i) q[i] -= d * v[k][i];
    }
    for (int i = 0; i < 9; ++i) basis[c][i] = q[i];
  }
  return true;
}

// Pieces of a cyclic Jacobi eigen decomposition, shared by SymmetricJacobi
// below (which the GPU's SmallestEigenvector runs too) and the warp's in
// warp_symmetric_jacobi.cuh.
// Squared off-diagonal and diagonal norms of the symmetric N x N matrix `a`,
// whose ratio stops the sweeps.
template <int N>
CASHASH_HOST_DEVICE inline void JacobiNorms(const double* a, double* off, double* diag) {
  *off = 0;
  *diag = 0;
  for (int p = 0; p < N; ++p) {
    *diag += a[p * N + p] * a[p * N + p];
    for (int q = p + 1; q < N; ++q) *off += a[p * N + q] * a[p * N + q];
  }
}

// The rotation (c, s) that zeroes the off-diagonal entry apq (non-zero).
CASHASH_HOST_DEVICE inline void JacobiRotation(double app, double aqq, double apq, double* c, double* s) {
  const double theta = (aqq - app) / (2 * apq);
  const double t = fabs(theta) > 1e150 ? 0.5 / theta : copysign(1.0, theta) / (fabs(theta) + sqrt(theta * theta + 1));
  *c = 1 / sqrt(t * t + 1);
  *s = t * *c;
}

// (x, y) <- (c x - s y, s x + c y).
CASHASH_HOST_DEVICE inline void RotatePair(double* x, double* y, double c, double s) {
  const double x0 = *x, y0 = *y;
  *x = c * x0 - s * y0;
  *y = s * x0 + c * y0;
}

// SymmetricJacobi's default stopping rule, which the warp's decomposition
// of E's local refit keeps too, so that both give the same basis.
constexpr int kJacobiMaxSweeps = 50;
constexpr double kJacobiTolerance = 1e-32;

// Cyclic Jacobi on the symmetric n x n matrix `a` (row-major, destroyed):
// eigenvalues on its diagonal, eigenvectors in the columns of `v`. Sweeps
// stop once the squared off-diagonal norm is at most `tolerance` times the
// diagonal's, or after `max_sweeps`.
template <int N>
CASHASH_HOST_DEVICE inline void SymmetricJacobi(double* a, double* v, int max_sweeps = kJacobiMaxSweeps,
                                                double tolerance = kJacobiTolerance) {
  for (int i = 0; i < N * N; ++i) v[i] = (i % (N + 1) == 0) ? 1.0 : 0.0;
  for (int sweep = 0; sweep < max_sweeps; ++sweep) {
    double off, diag;
    JacobiNorms<N>(a, &off, &diag);
    if (off <= tolerance * diag || off == 0) break;
    for (int p = 0; p < N - 1; ++p) {
      for (int q = p + 1; q < N; ++q) {
        const double apq = a[p * N + q];
        if (apq == 0) continue;
        double c, s;
        JacobiRotation(a[p * N + p], a[q * N + q], apq, &c, &s);
        for (int k = 0; k < N; ++k) RotatePair(&a[k * N + p], &a[k * N + q], c, s);  // columns p, q
        for (int k = 0; k < N; ++k) RotatePair(&a[p * N + k], &a[q * N + k], c, s);  // rows p, q
        for (int k = 0; k < N; ++k) RotatePair(&v[k * N + p], &v[k * N + q], c, s);
      }
    }
  }
}

// The basis from the normal matrix's eigen decomposition (SymmetricJacobi's
// `a` and `v`); the GPU's local refit runs the decomposition by a warp.
CASHASH_HOST_DEVICE inline void NullSpaceFromEigen(const double* a, const double* v, double (*basis)[9]) {
  // Order the eigenvalues (selection of the four smallest).
  int order[9];
  for (int i = 0; i < 9; ++i) order[i] = i;
  for (int i = 0; i < 4; ++i) {
    int best = i;
    for (int j = i + 1; j < 9; ++j)
      if (a[order[j] * 10] < a[order[best] * 10]) best = j;
    const int t = order[i];
    order[i] = order[best];
    order[best] = t;
  }
  const int slot[4] = {3, 0, 1, 2};
  for (int e = 0; e < 4; ++e)
    for (int i = 0; i < 9; ++i) basis[slot[e]][i] = v[i * 9 + order[e]];
}

// Entry (i, j) of the 9 x 9 normal matrix given by its 45 upper-triangle
// entries (row-major over i <= j).
CASHASH_HOST_DEVICE inline int NormalMatrixUpperIndex(int i, int j) {
  if (i > j) {
    const int t = i;
    i = j;
    j = t;
  }
  return i * 9 - i * (i - 1) / 2 + (j - i);
}

// Least-squares basis from the 9 x 9 normal matrix of >= 5 epipolar rows,
// given by its 45 upper-triangle entries (row-major over i <= j): the
// eigenvectors of the four smallest eigenvalues, the smallest as E4 (the
// constant term, so the solution sits near (x, y, z) = 0, as on the CPU).
CASHASH_HOST_DEVICE inline bool LeastSquaresNullSpace(const double* upper, double (*basis)[9]) {
  double a[81], v[81];
  for (int i = 0; i < 81; ++i) {
    a[i] = upper[NormalMatrixUpperIndex(i / 9, i % 9)];
    if (!isfinite(a[i])) return false;
  }
  SymmetricJacobi<9>(a, v);
  NullSpaceFromEigen(a, v, basis);
  return true;
}

// --- Polynomials in (x, y, z) ------------------------------------------------
// Linear: [x, y, z, 1]. Quadratic: [xx, xy, xz, yy, yz, zz, x, y, z, 1].
// Cubic (Nister's order, the 10 eliminated monomials first):
//   0 x^3, 1 y^3, 2 x^2y, 3 xy^2, 4 x^2z, 5 x^2, 6 y^2z, 7 y^2, 8 xyz, 9 xy,
//   10 xz^2, 11 xz, 12 x, 13 yz^2, 14 yz, 15 y, 16 z^3, 17 z^2, 18 z, 19 1.

CASHASH_HOST_DEVICE inline void MulLinear(const double* a, const double* b, double s, double* q) {
  q[0] += s * (a[0] * b[0]);
  q[1] += s * (a[0] * b[1] + a[1] * b[0]);
  q[2] += s * (a[0] * b[2] + a[2] * b[0]);
  q[3] += s * (a[1] * b[1]);
  q[4] += s * (a[1] * b[2] + a[2] * b[1]);
  q[5] += s * (a[2] * b[2]);
  q[6] += s * (a[0] * b[3] + a[3] * b[0]);
  q[7] += s * (a[1] * b[3] + a[3] * b[1]);
  q[8] += s * (a[2] * b[3] + a[3] * b[2]);
  q[9] += s * (a[3] * b[3]);
}

// c += s * q * l (quadratic times linear).
CASHASH_HOST_DEVICE inline void MulQuadLinear(const double* q, const double* l, double s, double* c) {
  const double xx = q[0], xy = q[1], xz = q[2], yy = q[3], yz = q[4], zz = q[5], x = q[6], y = q[7], z = q[8],
               one = q[9];
  const double lx = l[0], ly = l[1], lz = l[2], l1 = l[3];
  c[0] += s * (xx * lx);
  c[1] += s * (yy * ly);
  c[2] += s * (xx * ly + xy * lx);
  c[3] += s * (xy * ly + yy * lx);
  c[4] += s * (xx * lz + xz * lx);
  c[5] += s * (xx * l1 + x * lx);
  c[6] += s * (yy * lz + yz * ly);
  c[7] += s * (yy * l1 + y * ly);
  c[8] += s * (xy * lz + xz * ly + yz * lx);
  c[9] += s * (xy * l1 + x * ly + y * lx);
  c[10] += s * (xz * lz + zz * lx);
  c[11] += s * (xz * l1 + x * lz + z * lx);
  c[12] += s * (x * l1 + one * lx);
  c[13] += s * (yz * lz + zz * ly);
  c[14] += s * (yz * l1 + y * lz + z * ly);
  c[15] += s * (y * l1 + one * ly);
  c[16] += s * (zz * lz);
  c[17] += s * (zz * l1 + z * lz);
  c[18] += s * (z * l1 + one * lz);
  c[19] += s * (one * l1);
}

// The ten cubic constraints on (x, y, z): rows 0-8 the trace constraint
// (E E^T - trace(E E^T) / 2 I) E = 0, row 9 det(E) = 0.
CASHASH_HOST_DEVICE inline void ConstraintMatrix(const double (*basis)[9], double (*C)[20]) {
  double E[9][4];
  for (int i = 0; i < 9; ++i) {
    E[i][0] = basis[0][i];
    E[i][1] = basis[1][i];
    E[i][2] = basis[2][i];
    E[i][3] = basis[3][i];
  }
  for (int r = 0; r < 10; ++r)
    for (int m = 0; m < 20; ++m) C[r][m] = 0;
  double EEt[3][3][10];
  for (int i = 0; i < 3; ++i)
    for (int j = i; j < 3; ++j) {
      for (int m = 0; m < 10; ++m) EEt[i][j][m] = 0;
      for (int k = 0; k < 3; ++k) MulLinear(E[3 * i + k], E[3 * j + k], 1.0, EEt[i][j]);
    }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < i; ++j)
      for (int m = 0; m < 10; ++m) EEt[i][j][m] = EEt[j][i][m];
  for (int m = 0; m < 10; ++m) {
    const double half_trace = 0.5 * (EEt[0][0][m] + EEt[1][1][m] + EEt[2][2][m]);
    for (int i = 0; i < 3; ++i) EEt[i][i][m] -= half_trace;
  }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) MulQuadLinear(EEt[i][k], E[3 * k + j], 1.0, C[3 * i + j]);
  double minor[10];
  for (int m = 0; m < 10; ++m) minor[m] = 0;
  MulLinear(E[4], E[8], 1.0, minor);
  MulLinear(E[5], E[7], -1.0, minor);
  MulQuadLinear(minor, E[0], 1.0, C[9]);
  for (int m = 0; m < 10; ++m) minor[m] = 0;
  MulLinear(E[3], E[8], 1.0, minor);
  MulLinear(E[5], E[6], -1.0, minor);
  MulQuadLinear(minor, E[1], -1.0, C[9]);
  for (int m = 0; m < 10; ++m) minor[m] = 0;
  MulLinear(E[3], E[7], 1.0, minor);
  MulLinear(E[4], E[6], -1.0, minor);
  MulQuadLinear(minor, E[2], 1.0, C[9]);
}

// Polynomial product accumulation: out += s * a * b (ascending).
template <int NA, int NB>
CASHASH_HOST_DEVICE inline void PolyMulAdd(const double* a, const double* b, double s, double* out) {
  for (int i = 0; i < NA; ++i)
    for (int j = 0; j < NB; ++j) out[i + j] += s * a[i] * b[j];
}

// --- The solver ---------------------------------------------------------------

// The 3 x 3 system in z that the elimination leaves: rows i of
// x px(z) + y py(z) + p1(z) = 0 (px, py cubic, p1 quartic, ascending), and
// its determinant, a degree-10 polynomial whose real roots are the z of
// the solutions.
struct DeterminantSystem {
  double px[3][4], py[3][4], p1[3][5];
  double det[11];
};

// Gauss-Jordan elimination of the cubic constraints on E = x b0 + y b1 +
// z b2 + b3, then the system in z; false when the elimination breaks down.
// One function because it is one straight-line derivation on fixed device
// arrays: elimination of C, the px/py/p1 rows, their determinant in z.
CASHASH_HOST_DEVICE inline bool EliminateToDeterminant(const double (*basis)[9], DeterminantSystem* out) {
  double C[10][20];
  ConstraintMatrix(basis, C);
  // Gauss-Jordan on the first 10 columns with partial pivoting: each row
  // then reads "cubic monomial + combination of the last 10 = 0".
  double left_max = 0;
  for (int i = 0; i < 10; ++i)
    for (int j = 0; j < 10; ++j) left_max = fmax(left_max, fabs(C[i][j]));
  if (!(left_max > 0) || !isfinite(left_max)) return false;
  for (int k = 0; k < 10; ++k) {
    int p = k;
    for (int i = k + 1; i < 10; ++i)
      if (fabs(C[i][k]) > fabs(C[p][k])) p = i;
    if (!(fabs(C[p][k]) > 1e-14 * left_max)) return false;
    if (p != k)
      for (int j = k; j < 20; ++j) {
        const double t = C[k][j];
        C[k][j] = C[p][j];
        C[p][j] = t;
      }
    const double inv = 1.0 / C[k][k];
    for (int j = k + 1; j < 20; ++j) C[k][j] *= inv;
    C[k][k] = 1.0;
    // Rows 0-3 are not read once they have served as pivots.
    for (int i = k < 4 ? 0 : 4; i < 10; ++i) {
      if (i == k) continue;
      const double f = C[i][k];
      if (f == 0) continue;
      for (int j = k + 1; j < 20; ++j) C[i][j] -= f * C[k][j];
      C[i][k] = 0;
    }
  }
  // Rows (x^2z) - z (x^2), (y^2z) - z (y^2), (xyz) - z (xy): each is
  // x px(z) + y py(z) + p1(z) = 0 with px, py cubic and p1 quartic.
  double (*px)[4] = out->px;
  double (*py)[4] = out->py;
  double (*p1)[5] = out->p1;
  for (int i = 0; i < 3; ++i) {
    const double* a = C[4 + 2 * i] + 10;  // x^2z, y^2z, xyz
    const double* b = C[5 + 2 * i] + 10;  // x^2, y^2, xy
    // Basis columns: xz^2, xz, x, yz^2, yz, y, z^3, z^2, z, 1.
    px[i][3] = -b[0];
    px[i][2] = a[0] - b[1];
    px[i][1] = a[1] - b[2];
    px[i][0] = a[2];
    py[i][3] = -b[3];
    py[i][2] = a[3] - b[4];
    py[i][1] = a[4] - b[5];
    py[i][0] = a[5];
    p1[i][4] = -b[6];
    p1[i][3] = a[6] - b[7];
    p1[i][2] = a[7] - b[8];
    p1[i][1] = a[8] - b[9];
    p1[i][0] = a[9];
  }
  // det [px py p1] (rows i) = degree-10 polynomial in z.
  double m0[8] = {0}, m1[8] = {0}, m2[8] = {0};
  PolyMulAdd<4, 5>(py[1], p1[2], 1.0, m0);
  PolyMulAdd<4, 5>(py[2], p1[1], -1.0, m0);
  PolyMulAdd<4, 5>(py[0], p1[2], 1.0, m1);
  PolyMulAdd<4, 5>(py[2], p1[0], -1.0, m1);
  PolyMulAdd<4, 5>(py[0], p1[1], 1.0, m2);
  PolyMulAdd<4, 5>(py[1], p1[0], -1.0, m2);
  double* det = out->det;
  for (int i = 0; i < 11; ++i) det[i] = 0;
  PolyMulAdd<4, 8>(px[0], m0, 1.0, det);
  PolyMulAdd<4, 8>(px[1], m1, -1.0, det);
  PolyMulAdd<4, 8>(px[2], m2, 1.0, det);
  return true;
}

// The essential matrix (row-major, unit norm) at one root z of the
// determinant: (x, y, 1) is orthogonal to the three rows at z. False when
// they do not pin x and y down, or E is not finite.
CASHASH_HOST_DEVICE inline bool ModelAtRoot(const double (*basis)[9], const DeterminantSystem& system, double z,
                                            double* e) {
  double v[3][3];
  for (int i = 0; i < 3; ++i) {
    v[i][0] = sturm::Horner(system.px[i], 3, z);
    v[i][1] = sturm::Horner(system.py[i], 3, z);
    v[i][2] = sturm::Horner(system.p1[i], 4, z);
  }
  // (x, y, 1) is orthogonal to the three rows: the largest cross product.
  double best[3] = {0, 0, 0}, best_norm = -1;
  const int pairs[3][2] = {{0, 1}, {0, 2}, {1, 2}};
  for (int k = 0; k < 3; ++k) {
    const double* a = v[pairs[k][0]];
    const double* b = v[pairs[k][1]];
    const double c[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    const double norm = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
    if (norm > best_norm) {
      best_norm = norm;
      best[0] = c[0];
      best[1] = c[1];
      best[2] = c[2];
    }
  }
  if (!(fabs(best[2]) > 1e-12 * sqrt(best_norm))) return false;
  const double x = best[0] / best[2], y = best[1] / best[2];
  double norm2 = 0;
  for (int i = 0; i < 9; ++i) {
    e[i] = x * basis[0][i] + y * basis[1][i] + z * basis[2][i] + basis[3][i];
    norm2 += e[i] * e[i];
  }
  const double norm = sqrt(norm2);
  if (!(norm > 0) || !isfinite(norm)) return false;
  for (int i = 0; i < 9; ++i) e[i] /= norm;
  return true;
}

// Every essential matrix E = x b0 + y b1 + z b2 + b3 (row-major, unit norm)
// that satisfies the cubic constraints; returns their number (<= 10).
CASHASH_HOST_DEVICE inline int SolveFromBasis(const double (*basis)[9], double (*models)[9]) {
  DeterminantSystem system;
  if (!EliminateToDeterminant(basis, &system)) return 0;
  double zs[10];
  const int num_z = sturm::RealRoots(system.det, 10, zs);
  int num_models = 0;
  for (int r = 0; r < num_z; ++r)
    if (ModelAtRoot(basis, system, zs[r], models[num_models])) ++num_models;
  return num_models;
}

// The essential matrices through five correspondences (x1, y1, x2, y2 in
// normalised camera coordinates, pairs[4 k + 0..3]).
CASHASH_HOST_DEVICE inline int EssentialFromFivePoints(const double* pairs, double (*models)[9]) {
  double rows[5][9];
  for (int k = 0; k < 5; ++k)
    EpipolarCoefficients(pairs[4 * k], pairs[4 * k + 1], pairs[4 * k + 2], pairs[4 * k + 3], rows[k]);
  double basis[4][9];
  if (!MinimalNullSpace(rows, basis)) return 0;
  return SolveFromBasis(basis, models);
}

}  // namespace five_point
}  // namespace cashash
