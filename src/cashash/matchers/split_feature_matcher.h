// Several backends (one per GPU) behind one: every image is added to each
// of them, and the pairs of one Match or MatchExact call are cut into as
// many contiguous slices, matched at the same time on their own threads. A
// call is one chunk of the schedule (the pairs of a block pair), so the
// devices share every block pair; results come back in the callers' order,
// so the run is the same as with one backend (tested).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "cashash/matchers/exact_matcher.h"

namespace cashash {

class SplitFeatureMatcher : public MatchingBackend {
 public:
  // `parts` must not be empty; each is used by one thread at a time. The
  // traits are the first part's, named "<name> xN" for N > 1 parts;
  // guidance only where every part has it.
  explicit SplitFeatureMatcher(std::vector<std::unique_ptr<MatchingBackend>> parts);

  void AddImage(const Image& image) override;
  using FeatureMatcher::AddImage;
  void RemoveImage(image_t image_id) override;
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& guides = {}) override;
  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override;
  // Each part holds the pairs' images; the held matchers share the pairs
  // out as MatchExact does.
  std::unique_ptr<ExactMatcher> HoldForExact(const std::vector<ImagePair>& pairs) override;

  size_t num_parts() const { return parts_.size(); }

 private:
  std::vector<std::unique_ptr<MatchingBackend>> parts_;
};

// Slice k of n of `count` items: [begin, end), sizes differing by at most one.
void SliceBounds(size_t count, size_t k, size_t n, size_t* begin, size_t* end);

}  // namespace cashash
