// Matching and verifying one pair of images held in memory, without a
// database: the library call behind `cashash.match` in Python and behind
// any program that has its own features.
#pragma once

#include <functional>
#include <vector>

#include "cashash/matchers/feature_matcher.h"
#include "cashash/matching/matching_options.h"
#include "cashash/geometry/two_view_geometry.h"
#include "cashash/base/types.h"

namespace cashash {

struct PairMatchingOptions {
  SiftMatchingOptions sift;
  CasHashOptions cashash;
  TwoViewGeometryOptions two_view;
  // Return the raw matches only; also the case when an image has no
  // keypoints to verify with.
  bool skip_geometric_verification = false;

  // "" when valid, else a message naming the option.
  std::string Check() const;
};

struct PairMatchingResult {
  FeatureMatches matches;  // raw descriptor matches (image 1 row, image 2 row)
  // config is kUndefined when verification was skipped.
  TwoViewGeometry two_view_geometry;
  bool verified = false;
};

// A camera for images without known intrinsics, the way COLMAP guesses one:
// SIMPLE_RADIAL, focal 1.2 * max(width, height), principal point in the
// centre, no focal prior (so only F and H are estimated). When width or
// height is 0 the image is taken to span its keypoints.
Camera GuessCamera(const Keypoints& keypoints, uint64_t width = 0, uint64_t height = 0);

// Matches the descriptors of two images and, when both have keypoints (one
// per descriptor row), verifies the matches geometrically. A null camera is
// guessed with GuessCamera. `matcher` may be a backend the caller keeps (a
// GPU one, or one reused over many pairs); its image ids 0 and 1 are
// replaced. Null: a CPU matcher hashing with the mean of the two images,
// with the values chosen for the run decided for this pair, whose cascade
// matches are kept (auto: the cascade, by ChooseAutoMatcher; tau
// kCascadeTauForPrecision; no rematch; tables for its features).
// `after_matching`, where given, may change the pair's matches before they
// are verified (a run's exact rematch, pipeline/exact_rematch_stage.h).
// Throws std::invalid_argument for bad options or mismatched row counts.
using AfterPairMatching = std::function<void(const std::vector<ImagePair>&, std::vector<FeatureMatches>*)>;
PairMatchingResult MatchImagePair(const Keypoints& keypoints1, const FeatureDescriptors& descriptors1,
                                  const Keypoints& keypoints2, const FeatureDescriptors& descriptors2,
                                  const PairMatchingOptions& options, const Camera* camera1 = nullptr,
                                  const Camera* camera2 = nullptr, FeatureMatcher* matcher = nullptr,
                                  const AfterPairMatching& after_matching = nullptr);

}  // namespace cashash
