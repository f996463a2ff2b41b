// Synthetic two-view scenes with known geometry for the verification tests:
// a random 3-D point cloud (or plane) seen by two pinhole cameras, with
// pixel noise and a chosen fraction of random outlier matches.
#pragma once

#include <algorithm>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "cashash/geometry/point_pairs.h"
#include "cashash/base/types.h"
#include "ordered_draws.h"

namespace cashash {
namespace testing_support {

struct SceneOptions {
  int num_inliers = 700;
  double outlier_ratio = 0.3;  // fraction of all matches
  bool planar = false;
  double noise_px = 0.3;
  double baseline = 1.0;
  unsigned seed = 7;
};

struct SyntheticScene {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // cam2_from_cam1
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  int width = 1280, height = 960;
  std::vector<Eigen::Vector2d> points1, points2;  // pixels
  FeatureMatches matches;
  std::vector<bool> is_inlier;  // per match

  Eigen::Matrix3d TrueE() const {
    Eigen::Matrix3d tx;
    tx << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
    return tx * R;
  }
  Eigen::Matrix3d TrueF() const {
    const Eigen::Matrix3d Kinv = K.inverse();
    return Kinv.transpose() * TrueE() * Kinv;
  }
  Camera MakeCamera(bool prior) const {
    Camera c;
    c.model_id = 1;  // PINHOLE
    c.width = width;
    c.height = height;
    c.params = {K(0, 0), K(1, 1), K(0, 2), K(1, 2)};
    c.has_prior_focal_length = prior;
    return c;
  }
  // The matched pixels as point pairs, in match order.
  PointPairs Pairs() const {
    PointPairs p;
    p.resize(matches.size());
    for (size_t i = 0; i < matches.size(); ++i) {
      const auto& a = points1[matches[i].point2D_idx1];
      const auto& b = points2[matches[i].point2D_idx2];
      p.Set(i, a.x(), a.y(), b.x(), b.y());
    }
    return p;
  }
};

inline SyntheticScene MakeScene(const SceneOptions& options) {
  SyntheticScene s;
  std::mt19937 rng(options.seed);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  std::normal_distribution<double> noise(0.0, options.noise_px);
  s.K << 1000, 0, 640, 0, 1000, 480, 0, 0, 1;
  auto draw_uni = [&] { return uni(rng); };
  auto draw_noise = [&] { return noise(rng); };
  const auto a = DrawLastFirst<3>(draw_uni);
  const Eigen::Vector3d axis = Eigen::Vector3d(a[0], a[1], a[2]).normalized();
  s.R = Eigen::AngleAxisd(0.15 + 0.05 * uni(rng), axis).toRotationMatrix();
  const auto side = DrawLastFirst<2>(draw_uni);
  s.t = options.baseline * Eigen::Vector3d(1.0, 0.2 * side[0], 0.2 * side[1]).normalized();
  // Plane for planar scenes: z = 6 + 0.3 x + 0.2 y in camera 1.
  auto project = [&](const Eigen::Vector3d& X) -> Eigen::Vector2d {
    const Eigen::Vector3d p = s.K * X;
    return p.hnormalized();
  };
  auto inside = [&](const Eigen::Vector2d& p) {
    return p.x() >= 0 && p.x() < s.width && p.y() >= 0 && p.y() < s.height;
  };
  while (static_cast<int>(s.points1.size()) < options.num_inliers) {
    const auto u = DrawLastFirst<2>(draw_uni);
    const Eigen::Vector2d px((u[0] + 1) * 0.5 * s.width, (u[1] + 1) * 0.5 * s.height);
    const Eigen::Vector3d ray = s.K.inverse() * px.homogeneous();
    double depth;
    if (options.planar) {
      // Solve z = 6 + 0.3 x + 0.2 y along the ray (x = ray.x * z ...).
      depth = 6.0 / (1.0 - 0.3 * ray.x() - 0.2 * ray.y());
    } else {
      depth = 4.0 + 6.0 * (uni(rng) + 1) * 0.5;
    }
    const Eigen::Vector3d X = ray * depth;
    const Eigen::Vector3d X2 = s.R * X + s.t;
    if (X2.z() <= 0.1) continue;
    const Eigen::Vector2d p2 = project(X2);
    if (!inside(p2)) continue;
    const auto n1 = DrawLastFirst<2>(draw_noise);
    s.points1.push_back(px + Eigen::Vector2d(n1[0], n1[1]));
    const auto n2 = DrawLastFirst<2>(draw_noise);
    s.points2.push_back(p2 + Eigen::Vector2d(n2[0], n2[1]));
  }
  const int num_outliers = static_cast<int>(
      options.outlier_ratio / (1.0 - options.outlier_ratio) * options.num_inliers + 0.5);
  std::vector<bool> inlier(s.points1.size(), true);
  for (int i = 0; i < num_outliers; ++i) {
    const auto u1 = DrawLastFirst<2>(draw_uni);
    s.points1.emplace_back((u1[0] + 1) * 0.5 * s.width, (u1[1] + 1) * 0.5 * s.height);
    const auto u2 = DrawLastFirst<2>(draw_uni);
    s.points2.emplace_back((u2[0] + 1) * 0.5 * s.width, (u2[1] + 1) * 0.5 * s.height);
    inlier.push_back(false);
  }
  // Interleave inliers and outliers in a random but fixed order.
  std::vector<int> order(s.points1.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  std::shuffle(order.begin(), order.end(), rng);
  for (const int k : order) {
    FeatureMatch m;
    m.point2D_idx1 = static_cast<point2D_t>(k);
    m.point2D_idx2 = static_cast<point2D_t>(k);
    s.matches.push_back(m);
    s.is_inlier.push_back(inlier[k]);
  }
  return s;
}

}  // namespace testing_support
}  // namespace cashash
