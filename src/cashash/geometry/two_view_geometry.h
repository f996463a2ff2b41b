// Two-view geometric verification with COLMAP's semantics and defaults:
// F (7-point LO-RANSAC, Sampson error), H (4-point), E (5-point) when both
// cameras have a focal prior, and the same configuration decision.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "cashash/geometry/point_pairs.h"
#include "cashash/geometry/ransac_early_exit.h"
#include "cashash/base/types.h"

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
  // Stop E, F and H RANSAC early on pairs whose supports look like chance
  // (ransac_early_exit.h; not in COLMAP, which runs such pairs to
  // max_num_trials), and H and E once they cannot change the decision
  // (TwoViewRelevantHomographyInliers, TwoViewEssentialSettledInliers).
  // early_exit_max_risk bounds, under the chance model, the probability that
  // the full run would have reached min_num_inliers.
  bool early_exit = true;
  double early_exit_max_risk = 0.001;
  // Reject wrong hypotheses by a sequential test on a few dozen matches
  // before scoring them over all (ransac_sprt.h; both backends).
  // sprt_max_risk bounds the probability that a model which would have
  // beaten the best so far is rejected.
  bool sprt = true;
  double sprt_max_risk = 0.001;
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
// Equivalent to PrepareTwoViewPoints, EstimateFundamental,
// EstimateHomography (bounded by TwoViewRelevantHomographyInliers of F's
// count), EstimateEssential (calibrated pairs only, stopped at
// TwoViewEssentialSettledInliers of F's and H's counts) and
// DecideTwoViewGeometry in a row; a batch verifier (the GPU one) runs the
// same steps with F and H estimated elsewhere.
TwoViewGeometry EstimateTwoViewGeometry(const Camera& camera1,
                                        const std::vector<Eigen::Vector2d>& points1,
                                        const Camera& camera2,
                                        const std::vector<Eigen::Vector2d>& points2,
                                        const FeatureMatches& matches,
                                        const TwoViewGeometryOptions& options);

// ---------------------------------------------------------------------------
// The steps of EstimateTwoViewGeometry, for verifiers that estimate some of
// the models themselves and must still decide exactly as the CPU path does.

// Tags that give each estimator of a pair its own random stream
// (DeriveSeed(options.random_seed, tag)).
enum TwoViewSeedTag : uint64_t { kSeedF = 1, kSeedH = 2, kSeedE = 3, kSeedWatermark = 4 };

// The matched pixels of a pair (match order) and their normalised copy: each
// image centred, both scaled by one factor, so normalised errors are exactly
// norm.scale x pixel errors.
struct TwoViewPoints {
  PointPairs pixels;
  PointPairs normalized;
  PairNormalization norm;
};

TwoViewPoints PrepareTwoViewPoints(const std::vector<Eigen::Vector2d>& points1,
                                   const std::vector<Eigen::Vector2d>& points2,
                                   const FeatureMatches& matches);

// A pair with fewer matches than min_num_inliers is DEGENERATE without any
// estimation.
bool TooFewMatchesForTwoView(size_t num_matches, const TwoViewGeometryOptions& options);

// The chance test of E, F and H RANSAC (both backends) for these options.
RansacEarlyExitOptions TwoViewEarlyExitOptions(const TwoViewGeometryOptions& options);

// The sequential test's max_risk for these options; 0 when sprt is off.
float TwoViewSprtMaxRisk(const TwoViewGeometryOptions& options);

// With early_exit: the fewest H inliers that can change the decision, given
// F's count (0: F failed). H matters only above max_H_inlier_ratio x the
// count of the model it is compared with (F's, or E's, which is used only
// above min_E_F_inlier_ratio x F's), or, when E and F fail, from
// min_num_inliers on; below ratio x max(F's, min_num_inliers) it cannot.
// 0 when early_exit is off.
int TwoViewRelevantHomographyInliers(int num_F_inliers, const TwoViewGeometryOptions& options);
// The constant ratio of TwoViewRelevantHomographyInliers (both backends).
double TwoViewRelevantHomographyRatio(const TwoViewGeometryOptions& options);

// With early_exit: E's inlier count from which the pair is CALIBRATED
// whatever E finds later, given F's and H's counts (0 where that model
// failed) and the pair's matches (EssentialSettledInliers); E stops there
// (RansacOptions::settled_inliers): more trials would change which inliers
// are kept, not the decision. 0 when early_exit is off or no count settles
// it. E's chance test asks for min_num_inliers only, never F's higher
// count: asking for more can stop E before it finds the model F found and
// flip the pair to UNCALIBRATED (docs/gpu_verification.md).
int TwoViewEssentialSettledInliers(int num_F_inliers, int num_H_inliers, int num_matches,
                                   const TwoViewGeometryOptions& options);
// The fewest inliers EssentialSettledInliers may settle at for these
// options: min_num_inliers, and E's sample (E fails with fewer). The GPU's E
// takes it from here too, so both backends stop at the same count.
int TwoViewEssentialSettledMinInliers(const TwoViewGeometryOptions& options);

// One estimated model of a pair, as the decision reads it.
struct TwoViewModelEstimate {
  bool success = false;
  int num_inliers = 0;
  int num_trials = 0;
  // Stopped before COLMAP's loop would have: by the chance test
  // (ransac_early_exit.h), or where the model could no longer change the
  // decision (H below TwoViewRelevantHomographyInliers, E at
  // TwoViewEssentialSettledInliers).
  bool early_exit = false;
  // F and H in pixel coordinates (unit Frobenius norm); E in normalised
  // camera coordinates.
  Eigen::Matrix3d model = Eigen::Matrix3d::Zero();
  std::vector<char> inlier_mask;  // per match, when success
};

// COLMAP's RANSAC threshold of F and H in the normalised coordinates of
// `points`, squared (the value inlier residuals are compared against, in
// float).
double NormalizedSquaredThreshold(const TwoViewPoints& points, const TwoViewGeometryOptions& options);

// F and H by LO-RANSAC on the CPU.
TwoViewModelEstimate EstimateFundamental(const TwoViewPoints& points, const TwoViewGeometryOptions& options);
TwoViewModelEstimate EstimateHomography(const TwoViewPoints& points, const TwoViewGeometryOptions& options);
// The same, stopped once a model of `relevant_inliers` would have been found
// (RansacOptions::relevant_inliers; 0: COLMAP's loop).
TwoViewModelEstimate EstimateHomography(const TwoViewPoints& points, const TwoViewGeometryOptions& options,
                                        int relevant_inliers);

// Models found in normalised coordinates, mapped back to pixels and scaled
// to unit norm (as EstimateFundamental / EstimateHomography report them).
Eigen::Matrix3d FundamentalToPixels(const Eigen::Matrix3d& F_normalized, const PairNormalization& norm);
Eigen::Matrix3d HomographyToPixels(const Eigen::Matrix3d& H_normalized, const PairNormalization& norm);

// Both cameras have a focal prior and a model we can undistort: E is
// estimated and may decide the configuration.
bool TwoViewIsCalibrated(const Camera& camera1, const Camera& camera2);

// E by 5-point LO-RANSAC on undistorted, normalised camera coordinates.
TwoViewModelEstimate EstimateEssential(const Camera& camera1, const Camera& camera2, const PointPairs& pixels,
                                       const TwoViewGeometryOptions& options, int settled_inliers = 0);

// What EstimateEssential runs its RANSAC on: the matched pixels undistorted
// to normalised camera coordinates, and the threshold there (the pixel
// threshold through each camera's mean focal length, averaged). Other
// verifiers (the GPU one) estimate E from the same points and threshold.
struct EssentialPoints {
  PointPairs world;
  double max_error = 0;  // normalised camera units; residuals compare against its square
};
EssentialPoints PrepareEssentialPoints(const Camera& camera1, const Camera& camera2, const PointPairs& pixels,
                                       const TwoViewGeometryOptions& options);
// EstimateEssential on prepared points; with `settled_inliers`
// (TwoViewEssentialSettledInliers of the pair's F and H), stopped once E
// can no longer change the decision.
TwoViewModelEstimate EstimateEssential(const EssentialPoints& points, const TwoViewGeometryOptions& options,
                                       int settled_inliers = 0);

// COLMAP's configuration decision from the three estimates (E unused unless
// `calibrated`), then the inlier matches and the watermark test. F, H and E
// of the result are those of the estimates that succeeded.
TwoViewGeometry DecideTwoViewGeometry(const Camera& camera1, const Camera& camera2, const PointPairs& pixels,
                                      const FeatureMatches& matches, bool calibrated,
                                      const TwoViewModelEstimate& F, const TwoViewModelEstimate& H,
                                      const TwoViewModelEstimate& E, const TwoViewGeometryOptions& options);

}  // namespace cashash
