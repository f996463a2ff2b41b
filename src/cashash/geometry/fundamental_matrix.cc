#include "cashash/geometry/fundamental_matrix.h"

#include <Eigen/Dense>

#include "cashash/geometry/polynomial_roots.h"

namespace cashash {
namespace {

Eigen::Matrix3d FromRowMajor(const double* v) {
  Eigen::Matrix3d m;
  m << v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8];
  return m;
}

}  // namespace

int FundamentalSevenPoint(const PointPairs& pairs, const int* idx, Eigen::Matrix3d* models) {
  // The 7 epipolar constraints leave a 2-D null space {F1, F2}; the rank-2
  // condition det(F2 + a (F1 - F2)) = 0 is a cubic in a.
  Eigen::Matrix<double, 9, 7> At;
  for (int i = 0; i < 7; ++i) {
    const int k = idx[i];
    EpipolarRow(pairs, k, At.col(i).data());
  }
  const Eigen::HouseholderQR<Eigen::Matrix<double, 9, 7>> qr(At);
  const Eigen::Matrix<double, 9, 9> Q = qr.householderQ();
  const Eigen::Matrix<double, 9, 1> v1 = Q.col(7), v2 = Q.col(8);
  const Eigen::Matrix3d F1 = FromRowMajor(v1.data());
  const Eigen::Matrix3d F2 = FromRowMajor(v2.data());
  const Eigen::Matrix3d G = F1 - F2;

  // p(a) = det(F2 + a G) = c0 + c1 a + c2 a^2 + c3 a^3, from p(0), p(1),
  // p(-1) and the leading coefficient det(G).
  const double c0 = F2.determinant();
  const double c3 = G.determinant();
  const double p1 = F1.determinant();
  const double pm1 = (F2 - G).determinant();
  const double c2 = 0.5 * (p1 + pm1) - c0;
  const double c1 = 0.5 * (p1 - pm1) - c3;

  double roots[3];
  const int num_roots = SolveCubicReal(c3, c2, c1, c0, roots);
  for (int i = 0; i < num_roots; ++i) {
    Eigen::Matrix3d F = F2 + roots[i] * G;
    const double norm = F.norm();
    models[i] = norm > 0 ? Eigen::Matrix3d(F / norm) : F;
  }
  return num_roots;
}

bool FundamentalEightPoint(const PointPairs& pairs, const std::vector<int>& idx,
                           Eigen::Matrix3d* model) {
  if (idx.size() < 8) return false;
  // Normal equations of the stacked constraints: 9x9 regardless of the
  // inlier count, which keeps the local refit cheap.
  Eigen::Matrix<double, 9, 9> AtA = Eigen::Matrix<double, 9, 9>::Zero();
  Eigen::Matrix<double, 9, 1> row;
  for (const int k : idx) {
    EpipolarRow(pairs, k, row.data());
    AtA.selfadjointView<Eigen::Lower>().rankUpdate(row);
  }
  // The solver reads only the lower triangle, which is what rankUpdate filled.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> eig(AtA);
  const Eigen::Matrix<double, 9, 1> f = eig.eigenvectors().col(0);
  const Eigen::Matrix3d F = FromRowMajor(f.data());
  // Project onto rank 2.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d s = svd.singularValues();
  s(2) = 0;
  Eigen::Matrix3d F2 = svd.matrixU() * s.asDiagonal() * svd.matrixV().transpose();
  const double norm = F2.norm();
  if (!(norm > 0)) return false;
  *model = F2 / norm;
  return true;
}

}  // namespace cashash
