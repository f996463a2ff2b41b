#include "cashash/matchers/split_feature_matcher.h"

#include <exception>
#include <stdexcept>
#include <thread>

namespace cashash {

void SliceBounds(size_t count, size_t k, size_t n, size_t* begin, size_t* end) {
  *begin = count * k / n;
  *end = count * (k + 1) / n;
}

SplitFeatureMatcher::SplitFeatureMatcher(std::vector<std::unique_ptr<FeatureMatcher>> parts)
    : parts_(std::move(parts)) {
  if (parts_.empty()) throw std::invalid_argument("SplitFeatureMatcher needs at least one matcher");
}

void SplitFeatureMatcher::AddImage(image_t image_id, const FeatureDescriptors& descriptors) {
  for (auto& part : parts_) part->AddImage(image_id, descriptors);
}

void SplitFeatureMatcher::AddSharedImage(image_t image_id, std::shared_ptr<const FeatureDescriptors> descriptors) {
  for (auto& part : parts_) part->AddSharedImage(image_id, descriptors);
}

void SplitFeatureMatcher::RemoveImage(image_t image_id) {
  for (auto& part : parts_) part->RemoveImage(image_id);
}

namespace {

// Runs match(part, slice) for every part on its own thread (the first on
// the caller's) and concatenates the results in slice order. An exception
// of any part is rethrown after all threads have ended.
template <class Pair, class Match>
std::vector<FeatureMatches> MatchSlices(std::vector<std::unique_ptr<FeatureMatcher>>& parts,
                                        const std::vector<Pair>& pairs, const Match& match) {
  const size_t n = parts.size();
  if (n == 1 || pairs.size() < 2 * n) return match(*parts[0], pairs);
  std::vector<std::vector<FeatureMatches>> results(n);
  std::vector<std::exception_ptr> errors(n);
  auto run = [&](size_t k) {
    try {
      size_t begin = 0, end = 0;
      SliceBounds(pairs.size(), k, n, &begin, &end);
      const std::vector<Pair> slice(pairs.begin() + begin, pairs.begin() + end);
      results[k] = match(*parts[k], slice);
    } catch (...) {
      errors[k] = std::current_exception();
    }
  };
  std::vector<std::thread> threads;
  for (size_t k = 1; k < n; ++k) threads.emplace_back(run, k);
  run(0);
  for (std::thread& t : threads) t.join();
  for (const std::exception_ptr& e : errors) {
    if (e) std::rethrow_exception(e);
  }
  std::vector<FeatureMatches> all;
  all.reserve(pairs.size());
  for (auto& r : results) {
    for (FeatureMatches& m : r) all.push_back(std::move(m));
  }
  return all;
}

}  // namespace

std::vector<FeatureMatches> SplitFeatureMatcher::MatchPairs(const std::vector<ImagePair>& pairs) {
  return MatchSlices(parts_, pairs,
                     [](FeatureMatcher& m, const std::vector<ImagePair>& slice) { return m.MatchPairs(slice); });
}

std::vector<FeatureMatches> SplitFeatureMatcher::MatchPairsGuided(const std::vector<GuidedPair>& pairs,
                                                                  double max_distance) {
  return MatchSlices(parts_, pairs, [max_distance](FeatureMatcher& m, const std::vector<GuidedPair>& slice) {
    return m.MatchPairsGuided(slice, max_distance);
  });
}

bool SplitFeatureMatcher::SupportsExactMatching() const {
  for (const auto& part : parts_) {
    if (!part->SupportsExactMatching()) return false;
  }
  return true;
}

std::vector<FeatureMatches> SplitFeatureMatcher::MatchPairsExact(const std::vector<ImagePair>& pairs) {
  return MatchSlices(parts_, pairs,
                     [](FeatureMatcher& m, const std::vector<ImagePair>& slice) { return m.MatchPairsExact(slice); });
}

std::string SplitFeatureMatcher::Name() const {
  return parts_.size() == 1 ? parts_[0]->Name() : parts_[0]->Name() + " x" + std::to_string(parts_.size());
}

bool SplitFeatureMatcher::SupportsEpipolarGuidance() const {
  for (const auto& part : parts_) {
    if (!part->SupportsEpipolarGuidance()) return false;
  }
  return true;
}

}  // namespace cashash
