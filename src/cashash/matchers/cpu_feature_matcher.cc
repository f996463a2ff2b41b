// The CPU FeatureMatcher: Cascade Hashing or exact brute force, parallel over
// image pairs. Each pair is matched by one thread from per-image data built
// once in AddImage, so results do not depend on the number of threads.
#include <algorithm>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "cashash/matching/brute_force_matcher.h"
#include "cashash/matching/cascade_hashing.h"
#include "cashash/matching/cascade_matcher.h"
#include "cashash/matchers/exact_matcher.h"
#include "cashash/matching/table_shape.h"
#include "cashash/base/parallel_for.h"

namespace cashash {
namespace {

// What AddImage keeps for one image; only the member of the chosen matcher
// type is filled. Shared with the exact matchers HoldForExact hands out.
struct CpuImage {
  CascadeImage cascade;
  WideDescriptors wide;
  // Keypoint pixels of the hashed rows, x and y of row i at [2 i], [2 i + 1]
  // (EpipolarGuidance); empty where the image came without keypoints.
  std::vector<float> points;
};

using CpuImages = std::map<image_t, std::shared_ptr<const CpuImage>>;

const CpuImage* FindImage(const CpuImages& images, image_t image_id, const std::string& name) {
  const auto it = images.find(image_id);
  if (it == images.end()) {
    throw std::out_of_range("Match: image " + std::to_string(image_id) + " was not added to the " + name +
                            " matcher");
  }
  return it->second.get();
}

// Exact matches of pairs of held images: brute force needs the widened
// descriptors, which the cascade does not keep, so each pair widens its two
// images (linear, next to the quadratic matching).
std::vector<FeatureMatches> MatchCpuImagesExactly(const CpuImages& images, const std::vector<ImagePair>& pairs,
                                                  bool cascade, const SiftMatchingOptions& sift_options,
                                                  const std::string& name) {
  std::vector<const CpuImage*> firsts(pairs.size()), seconds(pairs.size());
  for (size_t i = 0; i < pairs.size(); ++i) {
    firsts[i] = FindImage(images, pairs[i].first, name);
    seconds[i] = FindImage(images, pairs[i].second, name);
  }
  std::vector<FeatureMatches> results(pairs.size());
  ParallelFor(pairs.size(), sift_options.num_threads, [&](size_t i) {
    if (!cascade) {
      results[i] = BruteForceMatchPair(firsts[i]->wide, seconds[i]->wide, sift_options);
      return;
    }
    const FeatureDescriptors& a = firsts[i]->cascade.descriptors;
    const FeatureDescriptors& b = seconds[i]->cascade.descriptors;
    results[i] = BruteForceMatchPair(WidenDescriptors(a, a.rows()), WidenDescriptors(b, b.rows()), sift_options);
  });
  return results;
}

// The images of some pairs as the backend held them, matched exactly on any
// thread (MatchingBackend::HoldForExact).
class HeldCpuImages : public ExactMatcher {
 public:
  HeldCpuImages(CpuImages images, bool cascade, const SiftMatchingOptions& sift_options, std::string name)
      : images_(std::move(images)), cascade_(cascade), sift_options_(sift_options), name_(std::move(name)) {}
  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override {
    return MatchCpuImagesExactly(images_, pairs, cascade_, sift_options_, name_);
  }

 private:
  const CpuImages images_;
  const bool cascade_;
  const SiftMatchingOptions sift_options_;
  const std::string name_;
};

MatcherTraits CpuTraits(const CasHashOptions& options) {
  MatcherTraits traits;
  const bool cascade = options.matcher == MatcherType::kCascade;
  traits.name = cascade ? "cpu-cascade" : "cpu-bruteforce";
  traits.epipolar_guidance = cascade;
  return traits;
}

class CpuFeatureMatcher : public MatchingBackend {
 public:
  CpuFeatureMatcher(const SiftMatchingOptions& sift_options, const CasHashOptions& options,
                    const MeanDescriptor& mean)
      : MatchingBackend(CpuTraits(options)),
        sift_options_(sift_options),
        // Tables still at 0 (chosen per run, table_shape.h): the shape of 8,192 features.
        options_(ResolveTableShape(options, 0)),
        mean_(mean) {
    std::string error = sift_options.Check();
    if (error.empty()) error = options.Check();
    if (!error.empty()) throw std::invalid_argument(error);
    if (cascade()) projections_ = GenerateCascadeProjections(options_);
  }

  void AddImage(const Image& image) override {
    const FeatureDescriptors& descriptors = *image.descriptors;
    const size_t num_rows =
        std::min(descriptors.rows(), static_cast<size_t>(sift_options_.max_num_matches));
    auto held = std::make_shared<CpuImage>();
    if (cascade()) {
      held->cascade = BuildCascadeImage(descriptors, num_rows, projections_, mean_);
      if (image.keypoints && image.keypoints->size() >= num_rows) {
        held->points.resize(2 * num_rows);
        for (size_t i = 0; i < num_rows; ++i) {
          held->points[2 * i] = (*image.keypoints)[i].x;
          held->points[2 * i + 1] = (*image.keypoints)[i].y;
        }
      }
    } else {
      held->wide = WidenDescriptors(descriptors, num_rows);
    }
    images_[image.id] = std::move(held);
  }
  using FeatureMatcher::AddImage;

  void RemoveImage(image_t image_id) override { images_.erase(image_id); }

  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& guides = {}) override {
    CheckGuides(pairs, guides);
    std::vector<const CpuImage*> firsts(pairs.size()), seconds(pairs.size());
    for (size_t i = 0; i < pairs.size(); ++i) {
      firsts[i] = FindImage(images_, pairs[i].first, Name());
      seconds[i] = FindImage(images_, pairs[i].second, Name());
      if (!guides.empty() && (firsts[i]->points.size() < 2 * firsts[i]->cascade.num_features() ||
                              seconds[i]->points.size() < 2 * seconds[i]->cascade.num_features())) {
        throw std::invalid_argument("Match: guided pair " + std::to_string(i) +
                                    " lacks keypoint positions for its features");
      }
    }
    std::vector<FeatureMatches> results(pairs.size());
    const size_t num_workers = NumParallelWorkers(pairs.size(), sift_options_.num_threads);
    std::vector<CascadeScratch> scratch(num_workers);
    ParallelForWorkers(pairs.size(), sift_options_.num_threads, [&](size_t i, size_t worker) {
      if (!cascade()) {
        results[i] = BruteForceMatchPair(firsts[i]->wide, seconds[i]->wide, sift_options_);
      } else if (guides.empty()) {
        results[i] = CascadeMatchPair(firsts[i]->cascade, seconds[i]->cascade, sift_options_, options_,
                                      &scratch[worker]);
      } else {
        EpipolarGuidance guidance;
        guidance.F = guides[i].F.data();
        guidance.points1 = firsts[i]->points.data();
        guidance.points2 = seconds[i]->points.data();
        guidance.max_distance = guides[i].max_distance;
        results[i] = CascadeMatchPairGuided(firsts[i]->cascade, seconds[i]->cascade, guidance, sift_options_,
                                            options_, &scratch[worker]);
      }
    });
    return results;
  }

  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override {
    return MatchCpuImagesExactly(images_, pairs, cascade(), sift_options_, Name());
  }

  std::unique_ptr<ExactMatcher> HoldForExact(const std::vector<ImagePair>& pairs) override {
    CpuImages held;
    for (const ImagePair& pair : pairs) {
      for (const image_t id : {pair.first, pair.second}) {
        FindImage(images_, id, Name());
        held.emplace(id, images_.at(id));
      }
    }
    return std::make_unique<HeldCpuImages>(std::move(held), cascade(), sift_options_, Name());
  }

 private:
  bool cascade() const { return options_.matcher == MatcherType::kCascade; }

  const SiftMatchingOptions sift_options_;
  const CasHashOptions options_;
  const MeanDescriptor mean_;
  CascadeProjections projections_;
  CpuImages images_;
};

}  // namespace

std::unique_ptr<MatchingBackend> CreateCpuFeatureMatcher(const SiftMatchingOptions& sift_options,
                                                         const CasHashOptions& cashash_options,
                                                         const MeanDescriptor& mean) {
  // Auto, tau and the rematch threshold chosen for the run are decided by
  // the run before any matcher is built (CasHashOptions::CheckDecided).
  const std::string undecided = cashash_options.CheckDecided();
  if (!undecided.empty()) throw std::invalid_argument(undecided);
  return std::make_unique<CpuFeatureMatcher>(sift_options, cashash_options, mean);
}

}  // namespace cashash
