// Ga-CasHash: two-stage, epipolar-guided Cascade Hashing matching (Xu, Sun
// and Tao, "GPU Accelerated Cascade Hashing Image Matching for Large Scale 3D
// Reconstruction", section "Image Matching with Geometry-aware Cascade
// Hashing on GPU").
//
// Stage 1 matches only the top_scale_fraction (20 %) largest-scale features
// of each image, for every pair. A pair with at least min_num_matches (16)
// stage-1 matches gets a fundamental matrix by RANSAC (the GPU's batched
// LO-RANSAC when matching on the GPU); if at least min_inlier_ratio (2/3) of
// its stage-1 matches are F inliers, stage 2 matches all features of the pair
// with each query's candidates restricted to the band of
// max_epipolar_distance pixels around its epipolar line (cascade_matcher.h,
// EpipolarGuidance). Every other pair gets no matches: the pipeline then
// verifies and writes it exactly as a pair for which exhaustive matching
// found none. Stage-2 matches are verified as usual. With unguided_fallback,
// a pair that has enough stage-1 matches but fails the inlier test is matched
// without the band instead (an addition to the paper, for unordered
// collections; see the option).
//
// GuidedFeatureMatcher does all of this behind the FeatureMatcher interface,
// so the pipeline, the scheduling, resuming and the database writer are the
// exhaustive matcher's own. It needs each image's keypoints, which the
// pipeline does not hand to matchers: KeypointRecordingSource, put between
// the pipeline and its feature source, keeps them for it.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "cashash/feature_matcher.h"
#include "cashash/matching_pipeline.h"
#include "cashash/two_view_geometry.h"
#include "cashash/types.h"

namespace cashash {

struct GuidedMatchingOptions {
  // Match with Ga-CasHash instead of exhaustively (--GuidedMatching.enabled,
  // or the guided_matcher command).
  bool enabled = false;
  // Share of each image's features, the largest scales, matched in stage 1.
  double top_scale_fraction = 0.2;
  // Fewest stage-1 matches for which F is estimated.
  int min_num_matches = 16;
  // Smallest share of the stage-1 matches that must be F inliers for the
  // pair to be matched in stage 2.
  double min_inlier_ratio = 2.0 / 3.0;
  // Half-width d (pixels) of the band around the epipolar line. The paper
  // gives no value. We take the verification threshold
  // (TwoViewGeometry.max_error, 4 px by default): stage-2 matches are
  // verified against an F fitted at that threshold, so a candidate farther
  // than that from the stage-1 F's line is, for an F that explains 2/3 of the
  // stage-1 matches, mostly one verification would reject anyway; and every
  // candidate dropped is one less rival in the ratio test. Measured with the
  // CPU cascade (docs/guided_matching.md): verified inlier matches on
  // fountain-P11 d = 2: 171,417, 4: 183,853, 8: 173,149, 16: 153,196;
  // sceaux_castle 2: 117,797, 4: 130,092, 8: 117,693 (the same pairs
  // verified at every d). Wider bands let more distractors into the ratio
  // test, narrower ones cut true matches where F is extrapolated.
  double max_epipolar_distance = 4.0;
  // Not in the paper. A pair with at least min_num_matches stage-1 matches
  // whose F explains fewer than min_inlier_ratio of them gets no matches in
  // the paper's method; with this set it is matched like exhaustive matching
  // does (all features, no band) and verified as usual. On an unordered
  // internet collection (sacre_coeur, docs/guided_matching.md) the pairs that
  // fail the test include the wide-baseline ones that join the view clusters:
  // without them colmap mapper found no initial pair there, with them every
  // image registered. Pairs with too few stage-1 matches still get none, so
  // far pairs of a large collection stay cheap. Off by default: the paper's
  // method.
  bool unguided_fallback = false;

  // "" when valid, else a message naming the option.
  std::string Check() const;
};

// A keypoint's scale from its affine shape: sqrt(|det A|), A = [a11 a12; a21
// a22] (the SIFT scale for similarity shapes, the 4-column scale for
// 4-column keypoints).
float KeypointScale(const Keypoint& keypoint);

// Rows (ascending) of the ceil(fraction * n) largest-scale keypoints among
// the first n = min(num_rows, keypoints.size()); equal scales go to the
// lower row. At least one row when n > 0.
std::vector<uint32_t> SelectTopScaleFeatures(const Keypoints& keypoints, size_t num_rows, double fraction);

// x, y of each of the first num_rows keypoints, interleaved (GuidedPair).
std::vector<float> InterleavedPositions(const Keypoints& keypoints, size_t num_rows);

// Estimates F of many pairs at once (stage 1).
class BatchFundamentalEstimator {
 public:
  virtual ~BatchFundamentalEstimator() = default;
  virtual std::string Name() const = 0;
  // F of each pair as EstimateFundamental gives it (pixel model, inlier
  // mask); pair k seeded from seeds[k] (DeriveSeed(seeds[k], kSeedF)).
  virtual std::vector<TwoViewModelEstimate> Estimate(const std::vector<const TwoViewPoints*>& pairs,
                                                     const std::vector<uint64_t>& seeds) = 0;
};

// EstimateFundamental per pair on num_threads threads (-1 = all cores).
std::unique_ptr<BatchFundamentalEstimator> CreateCpuFundamentalEstimator(const TwoViewGeometryOptions& options,
                                                                         int num_threads);

// What stage 1 decided for a pair.
enum class GuidedStage1Outcome {
  kTooFewMatches,  // fewer than min_num_matches stage-1 matches
  kFewInliers,     // F failed or explains less than min_inlier_ratio of them
  kGuided,         // stage 2 matches the pair within the epipolar band
};

GuidedStage1Outcome DecideGuidedStage1(size_t num_matches, const TwoViewModelEstimate* F,
                                       const GuidedMatchingOptions& options);

// A FeatureSource that passes everything through and keeps the keypoints of
// each loaded image until Take (or Clear) for GuidedFeatureMatcher.
class KeypointRecordingSource : public FeatureSource {
 public:
  explicit KeypointRecordingSource(FeatureSource* inner) : inner_(inner) {}
  // The source read through (may be set after construction, before use).
  void SetInner(FeatureSource* inner) { inner_ = inner; }
  ImageFeatures LoadFeatures(image_t image_id) override;
  const Camera& CameraOfImage(image_t image_id) const override { return inner_->CameraOfImage(image_id); }

  // The keypoints of the last load of image_id, removed from the store;
  // false when there are none.
  bool Take(image_t image_id, Keypoints* keypoints);
  // Drops what was not taken (images the matcher already holds).
  void Clear();

 private:
  FeatureSource* inner_;
  std::mutex mutex_;
  std::unordered_map<image_t, Keypoints> keypoints_;
};

struct GuidedMatchingStats {
  size_t pairs = 0;                 // pairs matched (stage 1)
  size_t pairs_enough_matches = 0;  // with >= min_num_matches stage-1 matches (F estimated)
  size_t pairs_guided = 0;          // passed the inlier test: matched in stage 2
  size_t pairs_fallback = 0;        // failed it, matched without the band (unguided_fallback)
  size_t stage1_matches = 0;
  size_t stage2_matches = 0;
  size_t fallback_matches = 0;
  double seconds_stage1 = 0;  // top-scale matching (and the images' subsets)
  double seconds_fundamental = 0;
  double seconds_stage2 = 0;  // guided matching
  double seconds_fallback = 0;  // matching without the band (unguided_fallback)
};

class GuidedFeatureMatcher : public FeatureMatcher {
 public:
  // full: matches all features in stage 2 (SupportsEpipolarGuidance());
  // top_scale: matches the stage-1 subsets (any backend, a separate
  // instance); keypoints: the source the pipeline loads through. The seed
  // is the run's RANSAC seed (pair seeds as in verification).
  GuidedFeatureMatcher(std::unique_ptr<FeatureMatcher> full, std::unique_ptr<FeatureMatcher> top_scale,
                       std::unique_ptr<BatchFundamentalEstimator> fundamental, KeypointRecordingSource* keypoints,
                       const GuidedMatchingOptions& options, int max_num_matches, uint64_t random_seed,
                       int num_threads);

  void AddImage(image_t image_id, const FeatureDescriptors& descriptors) override;
  void RemoveImage(image_t image_id) override;
  std::vector<FeatureMatches> MatchPairs(const std::vector<ImagePair>& pairs) override;
  // "guided(<full matcher>, F on <estimator>)"
  std::string Name() const override;

  const GuidedMatchingStats& stats() const { return stats_; }
  // Stage-1 outcome of each pair of the last MatchPairs call.
  const std::vector<GuidedStage1Outcome>& last_outcomes() const { return last_outcomes_; }

 private:
  struct GuidedImage {
    std::vector<uint32_t> top_scale_rows;          // stage-1 row -> row
    std::vector<Eigen::Vector2d> positions;        // pixels of the matched rows
    std::vector<float> interleaved;                // the same, for the band
  };
  const GuidedImage& Find(image_t image_id) const;

  std::unique_ptr<FeatureMatcher> full_;
  std::unique_ptr<FeatureMatcher> top_scale_;
  std::unique_ptr<BatchFundamentalEstimator> fundamental_;
  KeypointRecordingSource* keypoints_;
  const GuidedMatchingOptions options_;
  const size_t max_num_matches_;
  const uint64_t random_seed_;
  const int num_threads_;
  std::unordered_map<image_t, GuidedImage> images_;
  std::vector<GuidedStage1Outcome> last_outcomes_;
  GuidedMatchingStats stats_;
};

}  // namespace cashash
