#include "cashash/matchers/exact_rematch_feature_matcher.h"

#include <chrono>
#include <stdexcept>
#include <utility>

namespace cashash {

std::vector<FeatureMatches> FeatureMatcher::MatchPairsExact(const std::vector<ImagePair>&) {
  throw std::logic_error("the " + Name() + " matcher does not match from its own descriptors exactly");
}

ExactRematchFeatureMatcher::ExactRematchFeatureMatcher(std::unique_ptr<FeatureMatcher> cascade, size_t min_matches,
                                                       std::shared_ptr<ExactRematchCounts> counts)
    : cascade_(std::move(cascade)),
      min_matches_(min_matches),
      counts_(counts ? std::move(counts) : std::make_shared<ExactRematchCounts>()) {
  if (!cascade_) throw std::invalid_argument("ExactRematchFeatureMatcher needs a matcher");
  if (!cascade_->SupportsExactMatching()) {
    throw std::invalid_argument("ExactRematchFeatureMatcher: the " + cascade_->Name() +
                                " matcher cannot match exactly from its own descriptors");
  }
  if (min_matches_ == 0) throw std::invalid_argument("ExactRematchFeatureMatcher needs min_matches > 0");
}

void ExactRematchFeatureMatcher::AddImage(image_t image_id, const FeatureDescriptors& descriptors) {
  cascade_->AddImage(image_id, descriptors);
}

void ExactRematchFeatureMatcher::AddSharedImage(image_t image_id,
                                                std::shared_ptr<const FeatureDescriptors> descriptors) {
  cascade_->AddSharedImage(image_id, std::move(descriptors));
}

void ExactRematchFeatureMatcher::RemoveImage(image_t image_id) { cascade_->RemoveImage(image_id); }

std::vector<FeatureMatches> ExactRematchFeatureMatcher::MatchPairs(const std::vector<ImagePair>& pairs) {
  std::vector<FeatureMatches> results = cascade_->MatchPairs(pairs);
  std::vector<size_t> again;
  for (size_t i = 0; i < results.size(); ++i) {
    if (results[i].size() >= min_matches_) again.push_back(i);
  }
  counts_->pairs += pairs.size();
  if (again.empty()) return results;
  const auto start = std::chrono::steady_clock::now();
  std::vector<ImagePair> subset;
  subset.reserve(again.size());
  for (const size_t i : again) subset.push_back(pairs[i]);
  std::vector<FeatureMatches> exact = cascade_->MatchPairsExact(subset);
  for (size_t k = 0; k < again.size(); ++k) results[again[k]] = std::move(exact[k]);
  counts_->rematched += again.size();
  counts_->exact_us += std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now() - start)
                           .count();
  return results;
}

std::string ExactRematchFeatureMatcher::Name() const { return cascade_->Name() + "+exact-rematch"; }

bool ExactRematchFeatureMatcher::SupportsEpipolarGuidance() const { return cascade_->SupportsEpipolarGuidance(); }

std::vector<FeatureMatches> ExactRematchFeatureMatcher::MatchPairsGuided(const std::vector<GuidedPair>& pairs,
                                                                         double max_distance) {
  return cascade_->MatchPairsGuided(pairs, max_distance);
}

std::vector<FeatureMatches> ExactRematchFeatureMatcher::MatchPairsExact(const std::vector<ImagePair>& pairs) {
  return cascade_->MatchPairsExact(pairs);
}

}  // namespace cashash
