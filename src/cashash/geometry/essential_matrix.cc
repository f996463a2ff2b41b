#include "cashash/geometry/essential_matrix.h"

#include <array>
#include <cmath>
#include <complex>

#include <Eigen/Dense>

namespace cashash {
namespace {

// Polynomials of degree <= 3 in (x, y, z) over 20 monomials. The 10 cubic
// monomials come first and the 10 of degree <= 2 (the quotient basis) last:
// eliminating the cubic columns of the 10 constraints expresses every cubic
// monomial in the basis, which is exactly what the action matrix of "times x"
// needs, since x times a basis monomial is at most cubic.
constexpr int kNumMonomials = 20;
constexpr int kNumCubic = 10;
using Poly = std::array<double, kNumMonomials>;

struct MonomialTable {
  int exps[kNumMonomials][3];
  int index[4][4][4];  // exponent -> monomial index (degree <= 3), else -1
  MonomialTable() {
    int n = 0;
    for (int degree = 3; degree >= 0; --degree) {
      for (int a = degree; a >= 0; --a) {
        for (int b = degree - a; b >= 0; --b) {
          exps[n][0] = a;
          exps[n][1] = b;
          exps[n][2] = degree - a - b;
          ++n;
        }
      }
    }
    for (auto& plane : index)
      for (auto& row : plane)
        for (int& v : row) v = -1;
    for (int m = 0; m < kNumMonomials; ++m) index[exps[m][0]][exps[m][1]][exps[m][2]] = m;
  }
};

const MonomialTable& Monomials() {
  static const MonomialTable table;
  return table;
}

// Product of two polynomials whose degrees sum to at most 3.
Poly Multiply(const Poly& a, const Poly& b) {
  const MonomialTable& t = Monomials();
  // Higher degrees come first, so a polynomial's terms start at its first
  // non-zero slot: skipping the leading zeros bounds the loops by the degree.
  int first_a = 0, first_b = 0;
  while (first_a < kNumMonomials && a[first_a] == 0) ++first_a;
  while (first_b < kNumMonomials && b[first_b] == 0) ++first_b;
  Poly out{};
  for (int i = first_a; i < kNumMonomials; ++i) {
    for (int j = first_b; j < kNumMonomials; ++j) {
      const int ex = t.exps[i][0] + t.exps[j][0];
      const int ey = t.exps[i][1] + t.exps[j][1];
      const int ez = t.exps[i][2] + t.exps[j][2];
      if (ex + ey + ez > 3) continue;  // cannot happen for the products we form
      out[t.index[ex][ey][ez]] += a[i] * b[j];
    }
  }
  return out;
}

Poly Add(const Poly& a, const Poly& b, double sb = 1.0) {
  Poly out;
  for (int i = 0; i < kNumMonomials; ++i) out[i] = a[i] + sb * b[i];
  return out;
}

// The 4-D null space of the epipolar constraints, as 9-vectors (row-major E).
void NullSpace(const PointPairs& pairs, const int* idx, int count,
               Eigen::Matrix<double, 9, 4>* basis) {
  if (count == 5) {
    Eigen::Matrix<double, 9, 5> At;
    for (int i = 0; i < 5; ++i) EpipolarRow(pairs, idx[i], At.col(i).data());
    const Eigen::HouseholderQR<Eigen::Matrix<double, 9, 5>> qr(At);
    const Eigen::Matrix<double, 9, 9> Q = qr.householderQ();
    *basis = Q.rightCols<4>();
    return;
  }
  Eigen::Matrix<double, 9, 9> AtA = Eigen::Matrix<double, 9, 9>::Zero();
  Eigen::Matrix<double, 9, 1> row;
  for (int i = 0; i < count; ++i) {
    EpipolarRow(pairs, idx[i], row.data());
    AtA.selfadjointView<Eigen::Lower>().rankUpdate(row);
  }
  // The least-squares solution is nearest the smallest eigenvector: make it
  // the constant term E4, so the solution sits near (x, y, z) = 0 rather
  // than at infinity, where the elimination below would break down.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> eig(AtA);
  basis->col(3) = eig.eigenvectors().col(0);
  basis->leftCols<3>() = eig.eigenvectors().middleCols<3>(1);
}

}  // namespace

// One function because it is Nister's derivation in straight-line order
// (null-space basis, constraint matrix, elimination, action matrix, eigen
// solve), each step consuming the previous step's matrices and indices.
int EssentialFivePoint(const PointPairs& pairs, const int* idx, int count,
                       Eigen::Matrix3d* models) {
  if (count < 5) return 0;
  Eigen::Matrix<double, 9, 4> basis;
  NullSpace(pairs, idx, count, &basis);

  // E = x E1 + y E2 + z E3 + E4; each entry is a linear polynomial.
  const MonomialTable& t = Monomials();
  const int mx = t.index[1][0][0], my = t.index[0][1][0], mz = t.index[0][0][1];
  const int m1 = t.index[0][0][0];
  Poly E[3][3];
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      Poly p{};
      p[mx] = basis(3 * r + c, 0);
      p[my] = basis(3 * r + c, 1);
      p[mz] = basis(3 * r + c, 2);
      p[m1] = basis(3 * r + c, 3);
      E[r][c] = p;
    }
  }

  // Constraints: det(E) = 0 and 2 E E^T E - trace(E E^T) E = 0.
  Poly EEt[3][3];
  for (int i = 0; i < 3; ++i) {
    for (int j = i; j < 3; ++j) {
      Poly s{};
      for (int k = 0; k < 3; ++k) s = Add(s, Multiply(E[i][k], E[j][k]));
      EEt[i][j] = s;
      EEt[j][i] = s;
    }
  }
  const Poly trace = Add(Add(EEt[0][0], EEt[1][1]), EEt[2][2]);
  Eigen::Matrix<double, 10, kNumMonomials> C;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      Poly s{};
      for (int k = 0; k < 3; ++k) s = Add(s, Multiply(EEt[i][k], E[k][j]));
      const Poly eq = Add(Add(s, s), Multiply(trace, E[i][j]), -1.0);
      for (int m = 0; m < kNumMonomials; ++m) C(3 * i + j, m) = eq[m];
    }
  }
  const Poly minor0 = Add(Multiply(E[1][1], E[2][2]), Multiply(E[1][2], E[2][1]), -1.0);
  const Poly minor1 = Add(Multiply(E[1][0], E[2][2]), Multiply(E[1][2], E[2][0]), -1.0);
  const Poly minor2 = Add(Multiply(E[1][0], E[2][1]), Multiply(E[1][1], E[2][0]), -1.0);
  const Poly det = Add(Add(Multiply(E[0][0], minor0), Multiply(E[0][1], minor1), -1.0),
                       Multiply(E[0][2], minor2));
  for (int m = 0; m < kNumMonomials; ++m) C(9, m) = det[m];

  // Express the cubic monomials in the basis: cubic = -B * basis.
  const Eigen::Matrix<double, 10, 10> L = C.leftCols<kNumCubic>();
  const Eigen::Matrix<double, 10, 10> R = C.rightCols<kNumMonomials - kNumCubic>();
  const Eigen::FullPivLU<Eigen::Matrix<double, 10, 10>> lu(L);
  if (!lu.isInvertible()) return 0;
  const Eigen::Matrix<double, 10, 10> B = lu.solve(R);

  // Action matrix of multiplication by x on the basis monomials.
  Eigen::Matrix<double, 10, 10> action = Eigen::Matrix<double, 10, 10>::Zero();
  for (int b = 0; b < 10; ++b) {
    const int m = kNumCubic + b;
    const int product = t.index[t.exps[m][0] + 1][t.exps[m][1]][t.exps[m][2]];
    if (product < kNumCubic) {
      action.row(b) = -B.row(product);
    } else {
      action(b, product - kNumCubic) = 1.0;
    }
  }

  // Its eigenvectors are the basis monomials evaluated at the solutions.
  const Eigen::EigenSolver<Eigen::Matrix<double, 10, 10>> eig(action);
  if (eig.info() != Eigen::Success) return 0;
  const int bx = mx - kNumCubic, by = my - kNumCubic, bz = mz - kNumCubic, b1 = m1 - kNumCubic;
  // eigenvectors() returns a temporary: keep it, a column view of it would
  // dangle (AddressSanitizer: stack-use-after-scope).
  const Eigen::Matrix<std::complex<double>, 10, 10> vectors = eig.eigenvectors();
  int num_models = 0;
  for (int k = 0; k < 10; ++k) {
    const std::complex<double> lambda = eig.eigenvalues()(k);
    if (std::fabs(lambda.imag()) > 1e-8 * (1.0 + std::fabs(lambda.real()))) continue;
    const auto v = vectors.col(k);
    if (std::abs(v(b1)) < 1e-12) continue;
    const double x = (v(bx) / v(b1)).real();
    const double y = (v(by) / v(b1)).real();
    const double z = (v(bz) / v(b1)).real();
    Eigen::Matrix<double, 9, 1> e = x * basis.col(0) + y * basis.col(1) + z * basis.col(2) +
                                    basis.col(3);
    const double norm = e.norm();
    if (!(norm > 0) || !std::isfinite(norm)) continue;
    e /= norm;
    Eigen::Matrix3d Em;
    Em << e(0), e(1), e(2), e(3), e(4), e(5), e(6), e(7), e(8);
    models[num_models++] = Em;
  }
  return num_models;
}

}  // namespace cashash
