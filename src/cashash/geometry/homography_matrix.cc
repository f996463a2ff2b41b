#include "cashash/geometry/homography_matrix.h"

#include <cmath>

#include <Eigen/Dense>

namespace cashash {
namespace {

// The projective map sending e1, e2, e3 to p0, p1, p2 and (1,1,1) to p3:
// M = [p0 p1 p2] diag(l) with [p0 p1 p2] l = p3. False when degenerate.
bool BasisToPoints(const Eigen::Vector3d p[4], Eigen::Matrix3d* M) {
  Eigen::Matrix3d A;
  A << p[0], p[1], p[2];
  const double det = A.determinant();
  // Points are normalised to unit scale, so an absolute tolerance works.
  if (std::fabs(det) < 1e-10) return false;
  const Eigen::Vector3d l = A.inverse() * p[3];
  if ((l.array().abs() < 1e-10).any()) return false;
  *M = A * l.asDiagonal();
  return true;
}

}  // namespace

bool HomographyFourPoint(const PointPairs& pairs, const int* idx, Eigen::Matrix3d* model) {
  Eigen::Vector3d p1[4], p2[4];
  for (int i = 0; i < 4; ++i) {
    p1[i] << pairs.x1[idx[i]], pairs.y1[idx[i]], 1.0;
    p2[i] << pairs.x2[idx[i]], pairs.y2[idx[i]], 1.0;
  }
  Eigen::Matrix3d M1, M2;
  if (!BasisToPoints(p1, &M1) || !BasisToPoints(p2, &M2)) return false;
  const Eigen::Matrix3d H = M2 * M1.inverse();
  const double norm = H.norm();
  if (!(norm > 0) || !std::isfinite(norm)) return false;
  *model = H / norm;
  return true;
}

bool HomographyDlt(const PointPairs& pairs, const std::vector<int>& idx, Eigen::Matrix3d* model) {
  if (idx.size() < 4) return false;
  Eigen::Matrix<double, 9, 9> AtA = Eigen::Matrix<double, 9, 9>::Zero();
  Eigen::Matrix<double, 9, 1> r1, r2;
  for (const int k : idx) {
    const double x1 = pairs.x1[k], y1 = pairs.y1[k], x2 = pairs.x2[k], y2 = pairs.y2[k];
    r1 << -x1, -y1, -1, 0, 0, 0, x2 * x1, x2 * y1, x2;
    r2 << 0, 0, 0, -x1, -y1, -1, y2 * x1, y2 * y1, y2;
    AtA.selfadjointView<Eigen::Lower>().rankUpdate(r1);
    AtA.selfadjointView<Eigen::Lower>().rankUpdate(r2);
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> eig(AtA);
  const Eigen::Matrix<double, 9, 1> h = eig.eigenvectors().col(0);
  Eigen::Matrix3d H;
  H << h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), h(8);
  const double norm = H.norm();
  if (!(norm > 0) || !std::isfinite(norm)) return false;
  *model = H / norm;
  return true;
}

}  // namespace cashash
