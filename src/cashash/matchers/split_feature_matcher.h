// Several matchers (one per GPU) behind one FeatureMatcher: every image is
// added to each of them, and the pairs of one MatchPairs call are cut into
// as many contiguous slices, matched at the same time on their own threads.
// A call is one chunk of the schedule (the pairs of a block pair), so the
// devices share every block pair; results come back in the callers' order,
// so the run is the same as with one matcher (tested).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "cashash/matchers/feature_matcher.h"

namespace cashash {

class SplitFeatureMatcher : public FeatureMatcher {
 public:
  // `parts` must not be empty; each is used by one thread at a time.
  explicit SplitFeatureMatcher(std::vector<std::unique_ptr<FeatureMatcher>> parts);

  void AddImage(image_t image_id, const FeatureDescriptors& descriptors) override;
  void AddSharedImage(image_t image_id, std::shared_ptr<const FeatureDescriptors> descriptors) override;
  void RemoveImage(image_t image_id) override;
  std::vector<FeatureMatches> MatchPairs(const std::vector<ImagePair>& pairs) override;
  std::string Name() const override;
  bool SupportsEpipolarGuidance() const override;
  std::vector<FeatureMatches> MatchPairsGuided(const std::vector<GuidedPair>& pairs, double max_distance) override;
  bool SupportsExactMatching() const override;
  std::vector<FeatureMatches> MatchPairsExact(const std::vector<ImagePair>& pairs) override;

  size_t num_parts() const { return parts_.size(); }

 private:
  std::vector<std::unique_ptr<FeatureMatcher>> parts_;
};

// Slice k of n of `count` items: [begin, end), sizes differing by at most one.
void SliceBounds(size_t count, size_t k, size_t n, size_t* begin, size_t* end);

}  // namespace cashash
