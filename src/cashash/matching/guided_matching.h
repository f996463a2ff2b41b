// Ga-CasHash: two-stage, epipolar-guided Cascade Hashing matching (Xu, Sun
// and Tao, "GPU Accelerated Cascade Hashing Image Matching for Large Scale 3D
// Reconstruction", section "Image Matching with Geometry-aware Cascade
// Hashing on GPU"), with a stage 2 that cannot accept what exhaustive
// matching rejects.
//
// Stage 1 matches only the top_scale_fraction (20 %) largest-scale features
// of each image, for every pair. A pair with at least min_num_matches (16)
// stage-1 matches gets a fundamental matrix by RANSAC (the GPU's batched
// LO-RANSAC when matching on the GPU); if at least min_inlier_ratio (2/3) of
// its stage-1 matches are F inliers, stage 2 matches all features of the
// pair and keeps the matches that lie within max_epipolar_distance pixels of
// F's lines, both ways.
//
// Stage 2 by default takes the pair's exact matches (global nearest
// neighbour, ratio test and cross-check over the whole image: the matches
// exhaustive matching gives, ExactMatcher::MatchExact) and the band
// only filters them. The paper instead restricts each query's candidates to
// the band (restrict_search_to_band): then the ratio test only compares the
// few features that lie near the line, and a match on repeated structure
// along the right epipolar line passes where the whole image holds an
// equally good rival. Measured on fountain-P11, 62 % of the inliers that
// search adds are not their query's nearest neighbour in the image
// (docs/guided_matching.md); F cannot reject them, since they satisfy it.
// With the filter a band-only match cannot pass by construction.
//
// Pairs that stage 1 cannot guide but that show evidence of overlap are
// matched exactly without the band (unguided_fallback, on by default): those
// with fallback_min_num_matches (8) to min_num_matches stage-1 matches, and
// those whose F explains too few of them (wide baselines, the pairs that
// join the view clusters of unordered collections). Pairs with fewer
// stage-1 matches get no matches; the pipeline then verifies and writes them
// as pairs for which exhaustive matching found none. Far pairs of a large
// collection thus cost one stage-1 match of a fifth of the features.
//
// GuidedFeatureMatcher does all of this behind the FeatureMatcher interface,
// so the pipeline, the scheduling, resuming and the database writer are the
// exhaustive matcher's own. It needs each image's keypoints: its traits say
// uses_keypoints, so the pipeline adds its images with them.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "cashash/matchers/exact_matcher.h"
#include "cashash/geometry/two_view_geometry.h"
#include "cashash/base/types.h"

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
  // Half-width d (pixels) of the band around the stage-1 epipolar lines; 0
  // takes the default of the stage-2 method (EpipolarDistance()):
  // - 16 px for the filter of exact matches. The stage-1 F is fitted to the
  //   top-scale features at 4 px, and away from them its lines can be off by
  //   more: at 4 px the filter dropped 46 of the 179 verified inliers of one
  //   sacre_coeur pair and changed another pair's configuration, and the
  //   mapper's mean reprojection error rose 17 %; at 16 px guided keeps 97.9
  //   to 99.8 % of exhaustive matching's inliers on fountain-P11,
  //   herzjesu-P25, sceaux_castle and sacre_coeur (docs/guided_matching.md).
  //   The filter only removes outliers before verification; no match it
  //   keeps can be one exhaustive matching rejects.
  // - 4 px for the paper's search (restrict_search_to_band), whose value
  //   the paper does not give: the verification threshold. Measured with
  //   the CPU cascade, verified inlier matches on fountain-P11 d = 2:
  //   171,417, 4: 183,853, 8: 173,149, 16: 153,196: wider bands let more
  //   distractors into the ratio test among band candidates, narrower ones
  //   cut true matches where F is extrapolated.
  double max_epipolar_distance = 0;
  // Not in the paper. With this set, a pair that stage 1 cannot guide but
  // that shows evidence of overlap is matched exactly, without the band, and
  // verified as usual: pairs with at least fallback_min_num_matches stage-1
  // matches whose F cannot be estimated (fewer than min_num_matches) or
  // explains fewer than min_inlier_ratio of them. On an unordered internet
  // collection (sacre_coeur) the pairs that fail the inlier test include the
  // wide-baseline ones that join the view clusters: without them colmap
  // mapper found no initial pair. On fountain-P11, 9 of the 40 pairs
  // exhaustive matching verifies have fewer than 16 top-scale matches, 1
  // fewer than 8 (docs/guided_matching.md). Off: the paper's method, where
  // such pairs get no matches.
  bool unguided_fallback = true;
  // Fewest stage-1 matches for which a pair that is not guided is matched
  // without the band (unguided_fallback). Far pairs of a generated street
  // have a median of 0 and a 90th percentile of 4 chance stage-1 matches.
  int fallback_min_num_matches = 8;
  // The paper's stage 2: each query's candidates restricted to the band, the
  // ratio test among those. Off: exact matches filtered by the band (see the
  // top of this file); needs a backend with epipolar guidance (its traits)
  // when on.
  bool restrict_search_to_band = false;

  // "" when valid, else a message naming the option.
  std::string Check() const;
  // max_epipolar_distance, or its default for the stage-2 method when 0.
  double EpipolarDistance() const {
    if (max_epipolar_distance > 0) return max_epipolar_distance;
    return restrict_search_to_band ? 4.0 : 16.0;
  }
};

// A keypoint's scale from its affine shape: sqrt(|det A|), A = [a11 a12; a21
// a22] (the SIFT scale for similarity shapes, the 4-column scale for
// 4-column keypoints).
float KeypointScale(const Keypoint& keypoint);

// Rows (ascending) of the ceil(fraction * n) largest-scale keypoints among
// the first n = min(num_rows, keypoints.size()); equal scales go to the
// lower row. At least one row when n > 0.
std::vector<uint32_t> SelectTopScaleFeatures(const Keypoints& keypoints, size_t num_rows, double fraction);

// x, y of each of the first num_rows keypoints, interleaved (the band filter).
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
  kTooFewMatches,  // fewer than fallback_min_num_matches stage-1 matches (or min_num_matches
                   // without unguided_fallback): no matches
  kNoModel,        // enough for the fallback, too few to estimate F
  kFewInliers,     // F failed or explains less than min_inlier_ratio of them
  kGuided,         // stage 2 matches the pair within the epipolar band
};

GuidedStage1Outcome DecideGuidedStage1(size_t num_matches, const TwoViewModelEstimate* F,
                                       const GuidedMatchingOptions& options);

// The matches of one pair whose second point lies within max_distance
// pixels of the line F x1 and whose first point lies within max_distance of
// F^T x2 (epipolar_band.h; F row-major, x2^T F x1 = 0); xy1, xy2 are the
// images' interleaved keypoint pixels. Order is kept.
FeatureMatches KeepMatchesInEpipolarBand(const FeatureMatches& matches, const double* F, const std::vector<float>& xy1,
                                         const std::vector<float>& xy2, double max_distance);

struct GuidedMatchingStats {
  size_t pairs = 0;                 // pairs matched (stage 1)
  size_t pairs_enough_matches = 0;  // with >= min_num_matches stage-1 matches (F estimated)
  size_t pairs_guided = 0;          // passed the inlier test: matched in stage 2
  size_t pairs_weak = 0;            // fallback_min_num_matches to min_num_matches stage-1 matches
  size_t pairs_fallback = 0;        // weak or failed the inlier test, matched without the band
  size_t stage1_matches = 0;
  size_t stage2_exact_matches = 0;  // exact matches of the guided pairs before the band filter
  size_t stage2_matches = 0;
  size_t fallback_matches = 0;
  double seconds_stage1 = 0;  // top-scale matching (and the images' subsets)
  double seconds_fundamental = 0;
  double seconds_stage2 = 0;  // guided matching
  double seconds_fallback = 0;  // matching without the band (unguided_fallback)
  // Whether stage 2 searched within the band (restrict_search_to_band) or
  // filtered exact matches by it.
  bool searched_in_band = false;
};

// The run's report line: "Guided matching: N pairs, ...".
std::string DescribeGuidedMatching(const GuidedMatchingStats& stats, const GuidedMatchingOptions& options);

class GuidedFeatureMatcher : public FeatureMatcher {
 public:
  // full: matches all features in stage 2, exactly or (with
  // restrict_search_to_band) within the bands, which needs its traits'
  // epipolar_guidance; top_scale: matches the stage-1 subsets (any backend,
  // a separate instance). The seed is the run's RANSAC seed (pair seeds as
  // in verification). Images must be added with their keypoints (traits:
  // uses_keypoints).
  GuidedFeatureMatcher(std::unique_ptr<MatchingBackend> full, std::unique_ptr<FeatureMatcher> top_scale,
                       std::unique_ptr<BatchFundamentalEstimator> fundamental, const GuidedMatchingOptions& options,
                       int max_num_matches, uint64_t random_seed, int num_threads);

  void AddImage(const Image& image) override;
  using FeatureMatcher::AddImage;
  void RemoveImage(image_t image_id) override;
  // Guides are refused: this matcher makes its own.
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& guides = {}) override;

  const GuidedMatchingStats& stats() const { return stats_; }
  // Stage-1 outcome of each pair of the last Match call.
  const std::vector<GuidedStage1Outcome>& last_outcomes() const { return last_outcomes_; }

 private:
  struct GuidedImage {
    std::vector<uint32_t> top_scale_rows;          // stage-1 row -> row
    std::vector<Eigen::Vector2d> positions;        // pixels of the matched rows
    std::vector<float> interleaved;                // the same, for the band
  };
  const GuidedImage& Find(image_t image_id) const;

  std::unique_ptr<MatchingBackend> full_;
  std::unique_ptr<FeatureMatcher> top_scale_;
  std::unique_ptr<BatchFundamentalEstimator> fundamental_;
  const GuidedMatchingOptions options_;
  const size_t max_num_matches_;
  const uint64_t random_seed_;
  const int num_threads_;
  std::unordered_map<image_t, GuidedImage> images_;
  std::vector<GuidedStage1Outcome> last_outcomes_;
  GuidedMatchingStats stats_;
};

}  // namespace cashash
