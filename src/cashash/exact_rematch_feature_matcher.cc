#include "cashash/exact_rematch_feature_matcher.h"

#include <chrono>
#include <stdexcept>
#include <utility>

namespace cashash {

ExactRematchFeatureMatcher::ExactRematchFeatureMatcher(std::unique_ptr<FeatureMatcher> cascade,
                                                       std::unique_ptr<FeatureMatcher> exact, size_t min_matches,
                                                       std::shared_ptr<ExactRematchCounts> counts)
    : cascade_(std::move(cascade)),
      exact_(std::move(exact)),
      min_matches_(min_matches),
      counts_(counts ? std::move(counts) : std::make_shared<ExactRematchCounts>()) {
  if (!cascade_ || !exact_) throw std::invalid_argument("ExactRematchFeatureMatcher needs two matchers");
  if (min_matches_ == 0) throw std::invalid_argument("ExactRematchFeatureMatcher needs min_matches > 0");
}

void ExactRematchFeatureMatcher::AddImage(image_t image_id, const FeatureDescriptors& descriptors) {
  cascade_->AddImage(image_id, descriptors);
  exact_->AddImage(image_id, descriptors);
}

void ExactRematchFeatureMatcher::RemoveImage(image_t image_id) {
  cascade_->RemoveImage(image_id);
  exact_->RemoveImage(image_id);
}

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
  std::vector<FeatureMatches> exact = exact_->MatchPairs(subset);
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

}  // namespace cashash
