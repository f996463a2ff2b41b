// The interface every matching backend (CPU cascade, CPU brute force, GPU
// cascade, GPU brute force) and every wrapper implements, as narrow as
// COLMAP's FeatureMatcher: images are added and removed, pairs of added
// images are matched. The pipeline adds the images of the current block
// once, so per-image work (hash codes, bucket tables, device uploads) is done
// once per image and reused for all of its pairs.
//
// What a matcher can do beyond that is plain data fixed when it is built
// (MatcherTraits), not a question asked through the stack of wrappers, so a
// run's abilities do not depend on the order in which wrappers are stacked.
// Exact matching from the images a backend holds has an interface of its
// own (exact_matcher.h).
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "cashash/base/types.h"
#include "cashash/matching/matching_options.h"
#include "cashash/matching/mean_descriptor.h"

namespace cashash {

// One image as a matcher takes it. Ownership is shared with the caller (the
// pipeline's loaded features): a matcher that must keep the descriptors (the
// fallback to the CPU, to rebuild from) keeps the handle, not a copy.
struct MatcherImage {
  image_t id = 0;
  // May be null: only a matcher whose traits say uses_keypoints reads them
  // (guided matching), and a backend keeps them for guided pairs.
  std::shared_ptr<const Keypoints> keypoints;
  std::shared_ptr<const FeatureDescriptors> descriptors;
};

// Epipolar guidance of one pair (Ga-CasHash's stage 2, guided_matching.h):
// each query's candidates are restricted to the band of max_distance pixels
// around its epipolar line (cascade_matcher.h, EpipolarGuidance). The
// keypoints come from the pair's images (MatcherImage::keypoints).
struct EpipolarGuide {
  std::array<double, 9> F{};  // row-major, x2^T F x1 = 0 (pixels of first, second image)
  double max_distance = 0;
};

// What a matcher is and can do, fixed at construction.
struct MatcherTraits {
  // A short name for logs: "cpu-cascade", "gpu-bruteforce", ...
  std::string name;
  // Match accepts guides (the cascade backends); the guided pairs' images
  // must have been added with their keypoints.
  bool epipolar_guidance = false;
  // AddImage reads MatcherImage::keypoints (guided matching): its callers
  // must pass them. Other matchers take keypoints where given but do not
  // need them, so callers may leave them out.
  bool uses_keypoints = false;
};

class FeatureMatcher {
 public:
  using Image = MatcherImage;

  virtual ~FeatureMatcher() = default;

  // Makes an image available to Match. Descriptors beyond max_num_matches
  // rows are ignored. Adding an id twice replaces it.
  virtual void AddImage(const Image& image) = 0;
  // Frees what AddImage holds for this image.
  virtual void RemoveImage(image_t image_id) = 0;
  // Matches each pair (both images added before); result i belongs to pair i
  // and indexes (first image, second image) of that pair. `guides` is empty
  // or holds one guide per pair: then each pair is matched within its
  // epipolar band (needs traits().epipolar_guidance; std::logic_error
  // otherwise).
  virtual std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                            const std::vector<EpipolarGuide>& guides = {}) = 0;

  // AddImage for a caller that owns no shared descriptors (tests, one-pair
  // matching): the descriptors are copied once into a shared image.
  void AddImage(image_t image_id, const FeatureDescriptors& descriptors);

  const MatcherTraits& traits() const { return traits_; }
  const std::string& Name() const { return traits_.name; }

 protected:
  explicit FeatureMatcher(MatcherTraits traits) : traits_(std::move(traits)) {}

  // Throws std::logic_error unless `guides` is empty or, with epipolar
  // guidance, one per pair.
  void CheckGuides(const std::vector<ImagePair>& pairs, const std::vector<EpipolarGuide>& guides) const;

 private:
  MatcherTraits traits_;
};

}  // namespace cashash
