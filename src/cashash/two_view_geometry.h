// Two-view geometric verification with COLMAP's semantics and defaults:
// F (7-point LO-RANSAC, Sampson error), H (4-point), E (5-point) when both
// cameras have a focal prior, and the same configuration decision.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "cashash/types.h"

namespace cashash {

// COLMAP's TwoViewGeometry::ConfigurationType values, stored in the
// `config` column of two_view_geometries.
enum TwoViewConfig : int {
  kUndefined = 0,
  kDegenerate = 1,
  kCalibrated = 2,
  kUncalibrated = 3,
  kPlanar = 4,
  kPanoramic = 5,
  kPlanarOrPanoramic = 6,
  kWatermark = 7,
  kMultiple = 8,
};

struct TwoViewGeometryOptions {
  int min_num_inliers = 15;
  double min_E_F_inlier_ratio = 0.95;
  double max_H_inlier_ratio = 0.8;
  double watermark_min_inlier_ratio = 0.7;
  double watermark_border_size = 0.1;
  bool detect_watermark = true;
  // RANSAC (TwoViewGeometry.* / SiftMatching.* in COLMAP).
  double max_error = 4.0;  // pixels
  double confidence = 0.999;
  int min_num_trials = 100;
  int max_num_trials = 10000;
  double min_inlier_ratio = 0.25;
  // Base seed; each pair's RANSAC is seeded from it and the pair, so results
  // do not depend on thread scheduling.
  uint64_t random_seed = 0;

  std::string Check() const;
};

struct TwoViewGeometry {
  int config = kUndefined;
  // x2^T F x1 = 0, x2^T E x1 = 0 (normalised coordinates), x2 ~ H x1.
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d E = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  // cam2_from_cam1 as [w, x, y, z] and translation; identity unless computed.
  Eigen::Vector4d qvec = Eigen::Vector4d(1, 0, 0, 0);
  Eigen::Vector3d tvec = Eigen::Vector3d::Zero();
  FeatureMatches inlier_matches;

  // The same geometry seen from the swapped pair (image 2 first): F and E
  // transposed, H inverted, pose inverted, match columns swapped.
  TwoViewGeometry Inverted() const;
};

// Verifies `matches` between two images. points1/points2 are the keypoint
// positions (pixels) of the two images, indexed by the match indices.
TwoViewGeometry EstimateTwoViewGeometry(const Camera& camera1,
                                        const std::vector<Eigen::Vector2d>& points1,
                                        const Camera& camera2,
                                        const std::vector<Eigen::Vector2d>& points2,
                                        const FeatureMatches& matches,
                                        const TwoViewGeometryOptions& options);

}  // namespace cashash
