// COLMAP's two-view verification: F, H (and E with focal priors) by
// LO-RANSAC, the configuration decision, and the watermark check.
#include "cashash/geometry/two_view_geometry.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/Dense>

#include "cashash/geometry/camera_models.h"
#include "cashash/geometry/essential_matrix.h"
#include "cashash/geometry/fundamental_matrix.h"
#include "cashash/geometry/homography_matrix.h"
#include "cashash/geometry/point_pairs.h"
#include "cashash/geometry/ransac.h"
#include "cashash/geometry/translation_model.h"

namespace cashash {
namespace {

RansacOptions MakeRansacOptions(const TwoViewGeometryOptions& options, uint64_t tag) {
  RansacOptions r;
  r.max_error = options.max_error;
  r.confidence = options.confidence;
  r.min_num_trials = options.min_num_trials;
  r.max_num_trials = options.max_num_trials;
  r.min_inlier_ratio = options.min_inlier_ratio;
  r.seed = DeriveSeed(options.random_seed, tag);
  return r;
}

// E, F and H only: the watermark's translation model keeps the full budget.
RansacOptions MakeModelRansacOptions(const TwoViewGeometryOptions& options, uint64_t tag) {
  RansacOptions r = MakeRansacOptions(options, tag);
  r.early_exit = TwoViewEarlyExitOptions(options);
  r.sprt_max_risk = TwoViewSprtMaxRisk(options);
  return r;
}

FeatureMatches ExtractInlierMatches(const FeatureMatches& matches, const std::vector<char>& mask) {
  FeatureMatches inliers;
  for (size_t i = 0; i < matches.size(); ++i) {
    if (mask[i]) inliers.push_back(matches[i]);
  }
  return inliers;
}

// A point lies in the border band when it is outside the box shrunk by
// border_size x diagonal on every side (the box edges count as inside).
class BorderBand {
 public:
  BorderBand(const Camera& camera, double border_size)
      : w_(static_cast<double>(camera.width)), h_(static_cast<double>(camera.height)),
        band_(border_size * std::sqrt(w_ * w_ + h_ * h_)) {}
  bool Contains(double x, double y) const { return !(x >= band_ && x <= w_ - band_ && y >= band_ && y <= h_ - band_); }

 private:
  double w_, h_, band_;
};

// COLMAP's DetectWatermark: most inliers lie in the border band of both
// images and a single 2-D translation explains them. Every verified pair
// takes the first test, so it counts before it copies anything.
bool DetectWatermark(const Camera& camera1, const Camera& camera2, const PointPairs& pixels,
                     const std::vector<char>& inlier_mask, int num_inliers,
                     const TwoViewGeometryOptions& options) {
  if (num_inliers <= 0) return false;
  const BorderBand border1(camera1, options.watermark_border_size);
  const BorderBand border2(camera2, options.watermark_border_size);
  int in_border = 0;
  for (size_t i = 0; i < inlier_mask.size(); ++i) {
    if (inlier_mask[i] && border1.Contains(pixels.x1[i], pixels.y1[i]) &&
        border2.Contains(pixels.x2[i], pixels.y2[i])) {
      ++in_border;
    }
  }
  if (static_cast<double>(in_border) / num_inliers < options.watermark_min_inlier_ratio) {
    return false;
  }
  PointPairs inliers;
  inliers.resize(static_cast<size_t>(num_inliers));
  size_t j = 0;
  for (size_t i = 0; i < inlier_mask.size(); ++i) {
    if (inlier_mask[i]) inliers.Set(j++, pixels.x1[i], pixels.y1[i], pixels.x2[i], pixels.y2[i]);
  }
  inliers.resize(j);
  RansacOptions ransac = MakeRansacOptions(options, kSeedWatermark);
  ransac.min_inlier_ratio = options.watermark_min_inlier_ratio;
  const auto report = LoRansac(TranslationEstimator(inliers), ransac);
  const double ratio = static_cast<double>(std::max(0, report.support.num_inliers)) / num_inliers;
  return ratio >= options.watermark_min_inlier_ratio;
}

TwoViewModelEstimate ToEstimate(RansacReport<Eigen::Matrix3d>&& report) {
  TwoViewModelEstimate estimate;
  estimate.success = report.success;
  estimate.num_inliers = report.success ? report.support.num_inliers : 0;
  estimate.num_trials = report.num_trials;
  estimate.early_exit = report.early_exit;
  estimate.model = report.model;
  estimate.inlier_mask = std::move(report.inlier_mask);
  return estimate;
}

}  // namespace

std::string TwoViewGeometryOptions::Check() const {
  std::ostringstream error;
  auto in_unit = [&](const char* name, double value) {
    if (error.tellp() == 0 && !(value >= 0 && value <= 1)) {
      error << "TwoViewGeometry." << name << " must be in [0, 1]";
    }
  };
  if (min_num_inliers < 0) error << "TwoViewGeometry.min_num_inliers must be >= 0";
  in_unit("min_E_F_inlier_ratio", min_E_F_inlier_ratio);
  in_unit("max_H_inlier_ratio", max_H_inlier_ratio);
  in_unit("watermark_min_inlier_ratio", watermark_min_inlier_ratio);
  in_unit("watermark_border_size", watermark_border_size);
  if (error.tellp() == 0 && !(max_error > 0)) error << "TwoViewGeometry.max_error must be > 0";
  in_unit("confidence", confidence);
  in_unit("min_inlier_ratio", min_inlier_ratio);
  if (error.tellp() == 0 && min_num_trials < 0) {
    error << "TwoViewGeometry.min_num_trials must be >= 0";
  }
  if (error.tellp() == 0 && !(early_exit_max_risk > 0 && early_exit_max_risk < 1)) {
    error << "TwoViewGeometry.early_exit_max_risk must be in (0, 1)";
  }
  if (error.tellp() == 0 && !(sprt_max_risk > 0 && sprt_max_risk < 1)) {
    error << "TwoViewGeometry.sprt_max_risk must be in (0, 1)";
  }
  if (error.tellp() == 0 && max_num_trials < min_num_trials) {
    error << "TwoViewGeometry.max_num_trials must be >= min_num_trials";
  }
  return error.str();
}

RansacEarlyExitOptions TwoViewEarlyExitOptions(const TwoViewGeometryOptions& options) {
  RansacEarlyExitOptions early;
  early.min_num_inliers = options.early_exit ? std::max(1, options.min_num_inliers) : 0;
  early.max_risk = options.early_exit_max_risk;
  return early;
}

float TwoViewSprtMaxRisk(const TwoViewGeometryOptions& options) {
  return options.sprt ? static_cast<float>(options.sprt_max_risk) : 0.f;
}

double TwoViewRelevantHomographyRatio(const TwoViewGeometryOptions& options) {
  return options.max_H_inlier_ratio * options.min_E_F_inlier_ratio;
}

int TwoViewRelevantHomographyInliers(int num_F_inliers, const TwoViewGeometryOptions& options) {
  if (!options.early_exit) return 0;
  return RelevantInliers(TwoViewRelevantHomographyRatio(options), num_F_inliers, options.min_num_inliers);
}

int TwoViewEssentialSettledInliers(int num_F_inliers, int num_H_inliers, int num_matches,
                                   const TwoViewGeometryOptions& options) {
  if (!options.early_exit) return 0;
  return EssentialSettledInliers(options.min_E_F_inlier_ratio, options.max_H_inlier_ratio,
                                 TwoViewEssentialSettledMinInliers(options), num_F_inliers, num_H_inliers,
                                 num_matches);
}

int TwoViewEssentialSettledMinInliers(const TwoViewGeometryOptions& options) {
  // E succeeds only with a sample's worth of inliers (EssentialEstimator).
  return std::max(options.min_num_inliers, EssentialEstimator::kSampleSize);
}

TwoViewGeometry TwoViewGeometry::Inverted() const {
  TwoViewGeometry inv;
  inv.config = config;
  inv.F = F.transpose();
  inv.E = E.transpose();
  // An unset (zero) H stays zero rather than turning into NaNs.
  inv.H = H.isZero(0) ? H : Eigen::Matrix3d(H.inverse());
  inv.qvec = Eigen::Vector4d(qvec(0), -qvec(1), -qvec(2), -qvec(3));
  const Eigen::Quaterniond q(qvec(0), qvec(1), qvec(2), qvec(3));
  inv.tvec = -(q.normalized().toRotationMatrix().transpose() * tvec);
  inv.inlier_matches.reserve(inlier_matches.size());
  for (const FeatureMatch& m : inlier_matches) {
    FeatureMatch swapped;
    swapped.point2D_idx1 = m.point2D_idx2;
    swapped.point2D_idx2 = m.point2D_idx1;
    inv.inlier_matches.push_back(swapped);
  }
  return inv;
}

TwoViewPoints PrepareTwoViewPoints(const std::vector<Eigen::Vector2d>& points1,
                                   const std::vector<Eigen::Vector2d>& points2,
                                   const FeatureMatches& matches) {
  TwoViewPoints points;
  const size_t n = matches.size();
  points.pixels.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d& p1 = points1[matches[i].point2D_idx1];
    const Eigen::Vector2d& p2 = points2[matches[i].point2D_idx2];
    points.pixels.Set(i, p1.x(), p1.y(), p2.x(), p2.y());
  }
  // F and H run on a normalised copy; one common scale makes the errors
  // there exactly scale x the pixel errors.
  points.norm = NormalizePointPairs(points.pixels, &points.normalized);
  return points;
}

bool TooFewMatchesForTwoView(size_t num_matches, const TwoViewGeometryOptions& options) {
  return num_matches < static_cast<size_t>(std::max(0, options.min_num_inliers));
}

double NormalizedSquaredThreshold(const TwoViewPoints& points, const TwoViewGeometryOptions& options) {
  const double max_error = options.max_error * points.norm.scale;
  return max_error * max_error;
}

Eigen::Matrix3d FundamentalToPixels(const Eigen::Matrix3d& F_normalized, const PairNormalization& norm) {
  const Eigen::Matrix3d F = norm.T2.transpose() * F_normalized * norm.T1;
  return F / F.norm();
}

Eigen::Matrix3d HomographyToPixels(const Eigen::Matrix3d& H_normalized, const PairNormalization& norm) {
  const Eigen::Matrix3d H = norm.T2.inverse() * H_normalized * norm.T1;
  return H / H.norm();
}

TwoViewModelEstimate EstimateFundamental(const TwoViewPoints& points, const TwoViewGeometryOptions& options) {
  RansacOptions f_options = MakeModelRansacOptions(options, kSeedF);
  f_options.max_error = options.max_error * points.norm.scale;
  TwoViewModelEstimate F = ToEstimate(LoRansac(FundamentalEstimator(points.normalized), f_options));
  F.model = F.success ? FundamentalToPixels(F.model, points.norm) : Eigen::Matrix3d::Zero();
  return F;
}

TwoViewModelEstimate EstimateHomography(const TwoViewPoints& points, const TwoViewGeometryOptions& options) {
  return EstimateHomography(points, options, 0);
}

TwoViewModelEstimate EstimateHomography(const TwoViewPoints& points, const TwoViewGeometryOptions& options,
                                        int relevant_inliers) {
  RansacOptions h_options = MakeModelRansacOptions(options, kSeedH);
  h_options.relevant_inliers = relevant_inliers;
  h_options.max_error = options.max_error * points.norm.scale;
  TwoViewModelEstimate H = ToEstimate(LoRansac(HomographyEstimator(points.normalized), h_options));
  H.model = H.success ? HomographyToPixels(H.model, points.norm) : Eigen::Matrix3d::Zero();
  return H;
}

bool TwoViewIsCalibrated(const Camera& camera1, const Camera& camera2) {
  return camera1.has_prior_focal_length && camera2.has_prior_focal_length &&
         CameraModelIsSupported(camera1.model_id) && CameraModelIsSupported(camera2.model_id);
}

EssentialPoints PrepareEssentialPoints(const Camera& camera1, const Camera& camera2, const PointPairs& pixels,
                                       const TwoViewGeometryOptions& options) {
  EssentialPoints points;
  const size_t n = pixels.size();
  points.world.resize(n);
  for (size_t i = 0; i < n; ++i) {
    double u1, v1, u2, v2;
    CameraImageToWorld(camera1, pixels.x1[i], pixels.y1[i], &u1, &v1);
    CameraImageToWorld(camera2, pixels.x2[i], pixels.y2[i], &u2, &v2);
    points.world.Set(i, u1, v1, u2, v2);
  }
  // The pixel threshold mapped through each camera's focal length, averaged.
  points.max_error = 0.5 * (options.max_error / CameraMeanFocalLength(camera1) +
                            options.max_error / CameraMeanFocalLength(camera2));
  return points;
}

TwoViewModelEstimate EstimateEssential(const EssentialPoints& points, const TwoViewGeometryOptions& options,
                                       int settled_inliers) {
  RansacOptions e_options = MakeModelRansacOptions(options, kSeedE);
  e_options.max_error = points.max_error;
  e_options.settled_inliers = settled_inliers;
  TwoViewModelEstimate E = ToEstimate(LoRansac(EssentialEstimator(points.world), e_options));
  if (!E.success) E.model = Eigen::Matrix3d::Zero();
  return E;
}

TwoViewModelEstimate EstimateEssential(const Camera& camera1, const Camera& camera2, const PointPairs& pixels,
                                       const TwoViewGeometryOptions& options, int settled_inliers) {
  return EstimateEssential(PrepareEssentialPoints(camera1, camera2, pixels, options), options, settled_inliers);
}

TwoViewGeometry DecideTwoViewGeometry(const Camera& camera1, const Camera& camera2, const PointPairs& pixels,
                                      const FeatureMatches& matches, bool calibrated,
                                      const TwoViewModelEstimate& F, const TwoViewModelEstimate& H,
                                      const TwoViewModelEstimate& E_estimate,
                                      const TwoViewGeometryOptions& options) {
  TwoViewGeometry geometry;
  if (TooFewMatchesForTwoView(matches.size(), options)) {
    geometry.config = kDegenerate;
    return geometry;
  }
  // E takes part only for calibrated pairs.
  static const TwoViewModelEstimate kNoEstimate;
  const TwoViewModelEstimate& E = calibrated ? E_estimate : kNoEstimate;
  if (F.success) geometry.F = F.model;
  if (H.success) geometry.H = H.model;
  if (E.success) geometry.E = E.model;

  const int num_F = F.success ? F.num_inliers : 0;
  const int num_H = H.success ? H.num_inliers : 0;
  const int num_E = E.success ? E.num_inliers : 0;
  const int min_inliers = std::max(0, options.min_num_inliers);
  if ((!F.success && !H.success && !E.success) ||
      (num_F < min_inliers && num_H < min_inliers && num_E < min_inliers)) {
    geometry.config = kDegenerate;
    return geometry;
  }

  // Ratios as COLMAP computes them, division by zero included (an absent F
  // makes them infinite).
  const double E_F_ratio = static_cast<double>(num_E) / num_F;
  const double H_F_ratio = static_cast<double>(num_H) / num_F;
  const double H_E_ratio = static_cast<double>(num_H) / num_E;

  const std::vector<char>* mask = nullptr;
  int num_inliers = 0;
  auto use = [&](const TwoViewModelEstimate& estimate) {
    mask = &estimate.inlier_mask;
    num_inliers = estimate.num_inliers;
  };
  if (calibrated && E.success && E_F_ratio > options.min_E_F_inlier_ratio && num_E >= min_inliers) {
    // Calibrated: keep whichever of E and F explains more matches.
    use(num_E >= num_F ? E : F);
    if (H_E_ratio > options.max_H_inlier_ratio) {
      geometry.config = kPlanarOrPanoramic;
      if (num_H > num_inliers) use(H);
    } else {
      geometry.config = kCalibrated;
    }
  } else if (F.success && num_F >= min_inliers) {
    use(F);
    if (H_F_ratio > options.max_H_inlier_ratio) {
      geometry.config = kPlanarOrPanoramic;
      // COLMAP 4 keeps H's inliers on a tie; 3.8 kept F's in this branch.
      if (num_H >= num_F) use(H);
    } else {
      geometry.config = kUncalibrated;
    }
  } else if (H.success && num_H >= min_inliers) {
    use(H);
    geometry.config = kPlanarOrPanoramic;
  } else {
    geometry.config = kDegenerate;
    return geometry;
  }

  geometry.inlier_matches = ExtractInlierMatches(matches, *mask);
  if (options.detect_watermark &&
      DetectWatermark(camera1, camera2, pixels, *mask, num_inliers, options)) {
    geometry.config = kWatermark;
  }
  return geometry;
}

TwoViewGeometry EstimateTwoViewGeometry(const Camera& camera1,
                                        const std::vector<Eigen::Vector2d>& points1,
                                        const Camera& camera2,
                                        const std::vector<Eigen::Vector2d>& points2,
                                        const FeatureMatches& matches,
                                        const TwoViewGeometryOptions& options) {
  if (TooFewMatchesForTwoView(matches.size(), options)) {
    TwoViewGeometry geometry;
    geometry.config = kDegenerate;
    return geometry;
  }
  const TwoViewPoints points = PrepareTwoViewPoints(points1, points2, matches);
  const TwoViewModelEstimate F = EstimateFundamental(points, options);
  const TwoViewModelEstimate H =
      EstimateHomography(points, options, TwoViewRelevantHomographyInliers(F.success ? F.num_inliers : 0, options));
  const bool calibrated = TwoViewIsCalibrated(camera1, camera2);
  const TwoViewModelEstimate E =
      calibrated ? EstimateEssential(camera1, camera2, points.pixels, options,
                                     TwoViewEssentialSettledInliers(F.success ? F.num_inliers : 0,
                                                                    H.success ? H.num_inliers : 0,
                                                                    static_cast<int>(matches.size()), options))
                 : TwoViewModelEstimate();
  return DecideTwoViewGeometry(camera1, camera2, points.pixels, matches, calibrated, F, H, E, options);
}

}  // namespace cashash
