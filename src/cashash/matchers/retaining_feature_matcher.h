// Keeps images in the matcher after the pipeline lets them go, up to a
// memory budget, so that an image whose block comes back is not hashed (and,
// on the GPU, uploaded) again: with enough memory every image is hashed once
// for the whole run, whatever the block order. Past the budget the least
// recently released images are dropped first; images the pipeline holds are
// never dropped.
//
// Sound because an image id's descriptors do not change during a run, so a
// second AddImage of a kept image can be skipped.
#pragma once

#include <cstddef>
#include <functional>
#include <list>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "cashash/matchers/feature_matcher.h"

namespace cashash {

struct RetainingStats {
  size_t images_added = 0;    // AddImage calls passed to the wrapped matcher
  size_t images_reused = 0;   // AddImage calls answered by a kept image
  size_t images_dropped = 0;  // kept images removed to stay within the budget
  size_t peak_bytes = 0;      // most bytes held, by bytes_of
};

class RetainingFeatureMatcher : public FeatureMatcher {
 public:
  // bytes_of(descriptors): what the wrapped matcher holds for an image. The
  // traits are the wrapped matcher's.
  RetainingFeatureMatcher(std::unique_ptr<FeatureMatcher> inner, size_t budget_bytes,
                          std::function<size_t(const FeatureDescriptors&)> bytes_of);

  void AddImage(const Image& image) override;
  using FeatureMatcher::AddImage;
  void RemoveImage(image_t image_id) override;
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& guides = {}) override;

  const RetainingStats& stats() const { return stats_; }

 private:
  struct Kept {
    size_t bytes = 0;
    bool in_use = false;
    std::list<image_t>::iterator released;  // position in released_ when !in_use
  };
  void DropWhileOverBudget();

  std::unique_ptr<FeatureMatcher> inner_;
  size_t budget_bytes_;
  std::function<size_t(const FeatureDescriptors&)> bytes_of_;
  std::unordered_map<image_t, Kept> kept_;
  std::list<image_t> released_;  // oldest release first
  size_t bytes_ = 0;
  RetainingStats stats_;
};

}  // namespace cashash
