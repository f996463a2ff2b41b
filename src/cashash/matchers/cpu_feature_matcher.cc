// The CPU FeatureMatcher: Cascade Hashing or exact brute force, parallel over
// image pairs. Each pair is matched by one thread from per-image data built
// once in AddImage, so results do not depend on the number of threads.
#include <algorithm>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>

#include "cashash/matching/brute_force_matcher.h"
#include "cashash/matching/cascade_hashing.h"
#include "cashash/matching/cascade_matcher.h"
#include "cashash/matchers/feature_matcher.h"
#include "cashash/matching/table_shape.h"
#include "cashash/base/parallel_for.h"

namespace cashash {
namespace {

// What AddImage keeps for one image; only the member of the chosen matcher
// type is filled.
struct CpuImage {
  CascadeImage cascade;
  WideDescriptors wide;
};

class CpuFeatureMatcher : public FeatureMatcher {
 public:
  CpuFeatureMatcher(const SiftMatchingOptions& sift_options, const CasHashOptions& options,
                    const MeanDescriptor& mean)
      // Tables still at 0 (chosen per run, table_shape.h): the shape of 8,192 features.
      : sift_options_(sift_options), options_(ResolveTableShape(options, 0)), mean_(mean) {
    std::string error = sift_options.Check();
    if (error.empty()) error = options.Check();
    if (!error.empty()) throw std::invalid_argument(error);
    if (options_.matcher == MatcherType::kCascade) {
      projections_ = GenerateCascadeProjections(options_);
    }
  }

  void AddImage(image_t image_id, const FeatureDescriptors& descriptors) override {
    const size_t num_rows =
        std::min(descriptors.rows(), static_cast<size_t>(sift_options_.max_num_matches));
    auto image = std::make_shared<CpuImage>();
    if (options_.matcher == MatcherType::kCascade) {
      image->cascade = BuildCascadeImage(descriptors, num_rows, projections_, mean_);
    } else {
      image->wide = WidenDescriptors(descriptors, num_rows);
    }
    images_[image_id] = std::move(image);
  }

  void RemoveImage(image_t image_id) override { images_.erase(image_id); }

  std::vector<FeatureMatches> MatchPairs(const std::vector<ImagePair>& pairs) override {
    std::vector<const CpuImage*> firsts, seconds;
    FindImages(pairs, &firsts, &seconds);
    std::vector<FeatureMatches> results(pairs.size());
    const size_t num_workers = NumParallelWorkers(pairs.size(), sift_options_.num_threads);
    std::vector<CascadeScratch> scratch(num_workers);
    ParallelForWorkers(pairs.size(), sift_options_.num_threads, [&](size_t i, size_t worker) {
      if (options_.matcher == MatcherType::kCascade) {
        results[i] = CascadeMatchPair(firsts[i]->cascade, seconds[i]->cascade, sift_options_,
                                      options_, &scratch[worker]);
      } else {
        results[i] = BruteForceMatchPair(firsts[i]->wide, seconds[i]->wide, sift_options_);
      }
    });
    return results;
  }

  std::string Name() const override {
    return options_.matcher == MatcherType::kCascade ? "cpu-cascade" : "cpu-bruteforce";
  }

  bool SupportsEpipolarGuidance() const override { return options_.matcher == MatcherType::kCascade; }

  std::vector<FeatureMatches> MatchPairsGuided(const std::vector<GuidedPair>& pairs, double max_distance) override {
    if (!SupportsEpipolarGuidance()) return FeatureMatcher::MatchPairsGuided(pairs, max_distance);
    std::vector<const CpuImage*> firsts(pairs.size()), seconds(pairs.size());
    for (size_t i = 0; i < pairs.size(); ++i) {
      firsts[i] = Find(pairs[i].pair.first);
      seconds[i] = Find(pairs[i].pair.second);
      if (pairs[i].points1 == nullptr || pairs[i].points2 == nullptr ||
          pairs[i].points1->size() < 2 * firsts[i]->cascade.num_features() ||
          pairs[i].points2->size() < 2 * seconds[i]->cascade.num_features()) {
        throw std::invalid_argument("MatchPairsGuided: pair " + std::to_string(i) +
                                    " lacks keypoint positions for its features");
      }
    }
    std::vector<FeatureMatches> results(pairs.size());
    const size_t num_workers = NumParallelWorkers(pairs.size(), sift_options_.num_threads);
    std::vector<CascadeScratch> scratch(num_workers);
    ParallelForWorkers(pairs.size(), sift_options_.num_threads, [&](size_t i, size_t worker) {
      EpipolarGuidance guidance;
      guidance.F = pairs[i].F.data();
      guidance.points1 = pairs[i].points1->data();
      guidance.points2 = pairs[i].points2->data();
      guidance.max_distance = max_distance;
      results[i] = CascadeMatchPairGuided(firsts[i]->cascade, seconds[i]->cascade, guidance, sift_options_,
                                          options_, &scratch[worker]);
    });
    return results;
  }

  // Brute force needs the widened descriptors, which the cascade does not
  // keep: each pair widens its two images (linear, next to the quadratic
  // matching).
  bool SupportsExactMatching() const override { return true; }

  std::vector<FeatureMatches> MatchPairsExact(const std::vector<ImagePair>& pairs) override {
    if (options_.matcher != MatcherType::kCascade) return MatchPairs(pairs);  // already exact
    std::vector<const CpuImage*> firsts, seconds;
    FindImages(pairs, &firsts, &seconds);
    std::vector<FeatureMatches> results(pairs.size());
    ParallelFor(pairs.size(), sift_options_.num_threads, [&](size_t i) {
      const FeatureDescriptors& a = firsts[i]->cascade.descriptors;
      const FeatureDescriptors& b = seconds[i]->cascade.descriptors;
      results[i] = BruteForceMatchPair(WidenDescriptors(a, a.rows()), WidenDescriptors(b, b.rows()), sift_options_);
    });
    return results;
  }

 private:
  // Each pair's two images, looked up before the parallel loop (the map is
  // not touched by the workers).
  void FindImages(const std::vector<ImagePair>& pairs, std::vector<const CpuImage*>* firsts,
                  std::vector<const CpuImage*>* seconds) const {
    firsts->resize(pairs.size());
    seconds->resize(pairs.size());
    for (size_t i = 0; i < pairs.size(); ++i) {
      (*firsts)[i] = Find(pairs[i].first);
      (*seconds)[i] = Find(pairs[i].second);
    }
  }

  const CpuImage* Find(image_t image_id) const {
    const auto it = images_.find(image_id);
    if (it == images_.end()) {
      throw std::out_of_range("MatchPairs: image " + std::to_string(image_id) +
                              " was not added to the " + Name() + " matcher");
    }
    return it->second.get();
  }

  const SiftMatchingOptions sift_options_;
  const CasHashOptions options_;
  const MeanDescriptor mean_;
  CascadeProjections projections_;
  std::map<image_t, std::shared_ptr<const CpuImage>> images_;
};

}  // namespace

std::unique_ptr<FeatureMatcher> CreateCpuFeatureMatcher(const SiftMatchingOptions& sift_options,
                                                        const CasHashOptions& cashash_options,
                                                        const MeanDescriptor& mean) {
  // Auto is decided from the run's data before any matcher is built
  // (ChooseAutoMatcher, matcher_choice.h).
  if (cashash_options.matcher == MatcherType::kAuto) {
    throw std::invalid_argument("CasHash.matcher auto must be resolved (ChooseAutoMatcher) before a matcher is built");
  }
  return std::make_unique<CpuFeatureMatcher>(sift_options, cashash_options, mean);
}

}  // namespace cashash
