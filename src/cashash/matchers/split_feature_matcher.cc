#include "cashash/matchers/split_feature_matcher.h"

#include <exception>
#include <stdexcept>
#include <thread>
#include <utility>

namespace cashash {

void SliceBounds(size_t count, size_t k, size_t n, size_t* begin, size_t* end) {
  *begin = count * k / n;
  *end = count * (k + 1) / n;
}

namespace {

MatcherTraits SplitTraits(const std::vector<std::unique_ptr<MatchingBackend>>& parts) {
  if (parts.empty()) throw std::invalid_argument("SplitFeatureMatcher needs at least one matcher");
  MatcherTraits traits = parts[0]->traits();
  if (parts.size() > 1) traits.name += " x" + std::to_string(parts.size());
  for (const auto& part : parts) {
    traits.epipolar_guidance = traits.epipolar_guidance && part->traits().epipolar_guidance;
    traits.uses_keypoints = traits.uses_keypoints || part->traits().uses_keypoints;
  }
  return traits;
}

// Runs match(k, begin, end) for every part k on its own thread (the first on
// the caller's) over its slice [begin, end) of `count` pairs and
// concatenates the results in slice order. An exception of any part is
// rethrown after all threads have ended.
template <class Match>
std::vector<FeatureMatches> MatchSlices(size_t num_parts, size_t count, const Match& match) {
  const size_t n = num_parts;
  if (n == 1 || count < 2 * n) return match(0, 0, count);
  std::vector<std::vector<FeatureMatches>> results(n);
  std::vector<std::exception_ptr> errors(n);
  auto run = [&](size_t k) {
    try {
      size_t begin = 0, end = 0;
      SliceBounds(count, k, n, &begin, &end);
      results[k] = match(k, begin, end);
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
  all.reserve(count);
  for (auto& r : results) {
    for (FeatureMatches& m : r) all.push_back(std::move(m));
  }
  return all;
}

template <class T>
std::vector<T> Slice(const std::vector<T>& items, size_t begin, size_t end) {
  if (items.empty()) return {};
  return std::vector<T>(items.begin() + begin, items.begin() + end);
}

// The held images of every part, shared out as SplitFeatureMatcher shares
// out MatchExact.
class HeldSplitImages : public ExactMatcher {
 public:
  explicit HeldSplitImages(std::vector<std::unique_ptr<ExactMatcher>> parts) : parts_(std::move(parts)) {}
  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override {
    return MatchSlices(parts_.size(), pairs.size(), [&](size_t k, size_t begin, size_t end) {
      return parts_[k]->MatchExact(Slice(pairs, begin, end));
    });
  }

 private:
  std::vector<std::unique_ptr<ExactMatcher>> parts_;
};

}  // namespace

SplitFeatureMatcher::SplitFeatureMatcher(std::vector<std::unique_ptr<MatchingBackend>> parts)
    : MatchingBackend(SplitTraits(parts)), parts_(std::move(parts)) {}

void SplitFeatureMatcher::AddImage(const Image& image) {
  for (auto& part : parts_) part->AddImage(image);
}

void SplitFeatureMatcher::RemoveImage(image_t image_id) {
  for (auto& part : parts_) part->RemoveImage(image_id);
}

std::vector<FeatureMatches> SplitFeatureMatcher::Match(const std::vector<ImagePair>& pairs,
                                                       const std::vector<EpipolarGuide>& guides) {
  CheckGuides(pairs, guides);
  if (parts_.size() == 1) return parts_[0]->Match(pairs, guides);
  return MatchSlices(parts_.size(), pairs.size(), [&](size_t k, size_t begin, size_t end) {
    return parts_[k]->Match(Slice(pairs, begin, end), Slice(guides, begin, end));
  });
}

std::vector<FeatureMatches> SplitFeatureMatcher::MatchExact(const std::vector<ImagePair>& pairs) {
  if (parts_.size() == 1) return parts_[0]->MatchExact(pairs);
  return MatchSlices(parts_.size(), pairs.size(), [&](size_t k, size_t begin, size_t end) {
    return parts_[k]->MatchExact(Slice(pairs, begin, end));
  });
}

std::unique_ptr<ExactMatcher> SplitFeatureMatcher::HoldForExact(const std::vector<ImagePair>& pairs) {
  std::vector<std::unique_ptr<ExactMatcher>> held;
  for (auto& part : parts_) held.push_back(part->HoldForExact(pairs));
  return std::make_unique<HeldSplitImages>(std::move(held));
}

}  // namespace cashash
