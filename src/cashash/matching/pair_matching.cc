#include "cashash/matching/pair_matching.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>

#include <Eigen/Core>

#include "cashash/matchers/exact_matcher.h"
#include "cashash/matching/matcher_choice.h"
#include "cashash/matching/table_shape.h"

namespace cashash {
namespace {

constexpr int kSimpleRadialModelId = 2;

void CheckRows(const Keypoints& keypoints, const FeatureDescriptors& descriptors, const char* which) {
  if (descriptors.data.size() % kDescriptorDim != 0) {
    throw std::invalid_argument(std::string("descriptors of image ") + which + " are not rows of " +
                                std::to_string(kDescriptorDim) + " bytes");
  }
  if (!keypoints.empty() && keypoints.size() != descriptors.rows()) {
    throw std::invalid_argument(std::string("image ") + which + " has " + std::to_string(keypoints.size()) +
                                " keypoints but " + std::to_string(descriptors.rows()) + " descriptors");
  }
}

std::vector<Eigen::Vector2d> Positions(const Keypoints& keypoints) {
  std::vector<Eigen::Vector2d> points;
  points.reserve(keypoints.size());
  for (const Keypoint& k : keypoints) points.emplace_back(k.x, k.y);
  return points;
}

}  // namespace

std::string PairMatchingOptions::Check() const {
  std::string message = sift.Check();
  if (!message.empty()) return message;
  message = cashash.Check();
  if (!message.empty()) return message;
  return two_view.Check();
}

Camera GuessCamera(const Keypoints& keypoints, uint64_t width, uint64_t height) {
  if (width == 0 || height == 0) {
    float max_x = 1.f, max_y = 1.f;
    for (const Keypoint& k : keypoints) {
      max_x = std::max(max_x, k.x);
      max_y = std::max(max_y, k.y);
    }
    width = static_cast<uint64_t>(std::ceil(max_x));
    height = static_cast<uint64_t>(std::ceil(max_y));
  }
  Camera camera;
  camera.model_id = kSimpleRadialModelId;
  camera.width = width;
  camera.height = height;
  const double focal = 1.2 * static_cast<double>(std::max(width, height));
  camera.params = {focal, 0.5 * static_cast<double>(width), 0.5 * static_cast<double>(height), 0.0};
  camera.has_prior_focal_length = false;
  return camera;
}

PairMatchingResult MatchImagePair(const Keypoints& keypoints1, const FeatureDescriptors& descriptors1,
                                  const Keypoints& keypoints2, const FeatureDescriptors& descriptors2,
                                  const PairMatchingOptions& options, const Camera* camera1, const Camera* camera2,
                                  FeatureMatcher* matcher, const AfterPairMatching& after_matching) {
  const std::string problem = options.Check();
  if (!problem.empty()) throw std::invalid_argument(problem);
  CheckRows(keypoints1, descriptors1, "1");
  CheckRows(keypoints2, descriptors2, "2");

  std::unique_ptr<FeatureMatcher> own_matcher;
  if (matcher == nullptr) {
    // The values chosen for the run are decided for this one pair with the
    // runs' rules. This matcher keeps the cascade's own matches: a rematch
    // threshold left chosen is none, auto is the cascade
    // (ChooseAutoMatcher) and tau left chosen is the one for precision
    // (kCascadeTauForPrecision, as ChooseCascadeTau gives without a
    // rematch). Tables at 0: chosen for the larger of the two
    // images.
    const size_t features =
        TypicalFeatureCount({descriptors1.rows(), descriptors2.rows()}, options.sift.max_num_matches);
    MatcherChoiceInput input;
    input.on_gpu = false;
    input.features_per_image = features;
    input.rematch_from_rule = false;
    CasHashOptions cashash = options.cashash;
    if (cashash.exact_rematch_min_matches == kRematchMinMatchesChosen) cashash.exact_rematch_min_matches = 0;
    cashash = ResolveTableShape(ApplyMatcherChoice(cashash, ChooseAutoMatcher(cashash, input)), features);
    if (cashash.tau == kTauChosen) cashash.tau = kCascadeTauForPrecision;
    own_matcher = CreateCpuFeatureMatcher(options.sift, cashash, ComputeMeanDescriptor({&descriptors1, &descriptors2}));
    matcher = own_matcher.get();
  }
  matcher->AddImage(0, descriptors1);
  matcher->AddImage(1, descriptors2);
  PairMatchingResult result;
  const std::vector<ImagePair> pairs = {ImagePair(0, 1)};
  std::vector<FeatureMatches> matches = matcher->Match(pairs);
  if (after_matching) after_matching(pairs, &matches);
  result.matches = std::move(matches.front());
  matcher->RemoveImage(0);
  matcher->RemoveImage(1);

  if (options.skip_geometric_verification || keypoints1.empty() || keypoints2.empty()) return result;
  const Camera guessed1 = camera1 == nullptr ? GuessCamera(keypoints1) : Camera();
  const Camera guessed2 = camera2 == nullptr ? GuessCamera(keypoints2) : Camera();
  result.two_view_geometry =
      EstimateTwoViewGeometry(camera1 ? *camera1 : guessed1, Positions(keypoints1), camera2 ? *camera2 : guessed2,
                              Positions(keypoints2), result.matches, options.two_view);
  result.verified = true;
  return result;
}

}  // namespace cashash
