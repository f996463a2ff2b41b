// The cascade screens, exact matching decides: every pair is matched by the
// cascade; a pair that keeps at least `min_matches` matches (one that may
// verify) is matched again exactly, by the same backend from the
// descriptors it already holds (FeatureMatcher::MatchPairsExact), and the
// exact matches replace the cascade's.
//
// Why: the cascade's first level misses true matches whose hash bits differ
// in every table. On photographs with changing light and viewpoint that is
// several percent of them (sacre_coeur at 3,072 features: recall 0.938 at
// 8 x 7; docs/cascade_parameters.md), and those are the pairs where few
// matches decide whether a pair verifies and how many inliers it keeps. The
// pairs that can verify are a small share of an exhaustive run's pairs (9 %
// of a 300-image street, 0.3 % of a 5,000-image one), so matching them
// exactly costs little next to screening all pairs with the cascade, and
// their raw matches, inliers and two-view geometry are exact matching's,
// as COLMAP's. Pairs below the threshold keep the cascade's matches: with
// fewer than min_num_inliers (15) of them RANSAC is not run at all.
//
// Deferred (with an ExactMatcherPool): MatchPairsDeferred returns the
// cascade's matches at once and leaves the exact matching of the chunk's
// pairs to DeferredMatching::Complete, which the pipeline runs on a
// verification thread. The matching thread then goes on with the next
// chunk's cascade: on the GPU the rematch was a quarter to a third of the
// matching thread's time at 300 images (0.45 s of 1.24-1.30 s), and the
// verification threads were idle for a third of theirs.
// Complete uses the cascade's ticket (FeatureMatcher::DeferExactMatching:
// the GPU cascade lends the descriptors it holds on the device) where it
// gives one, else a brute-force matcher from the pool, fed with the
// descriptors the chunk holds. A ticket that runs out of device memory
// (DeviceMemoryError) hands its pairs to the pool as well, whose GPU
// matchers go on on the CPU when the device has no room for them either
// (CreateFallbackFeatureMatcher): out of memory in the rematch costs time,
// never the run.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "cashash/base/object_pool.h"
#include "cashash/matchers/feature_matcher.h"

namespace cashash {

// What a run's rematching did, for its log; shared with the run because the
// matcher sits inside other wrappers.
struct ExactRematchCounts {
  std::atomic<size_t> pairs{0};      // matched by the cascade
  std::atomic<size_t> rematched{0};  // of those, matched again exactly
  std::atomic<int64_t> exact_us{0};  // wall time of the exact matching
  // Deferred rematches whose ticket found no room on the device
  // (DeviceMemoryError) and were matched by the pool's matchers instead.
  std::atomic<size_t> tickets_without_memory{0};
};

// Brute-force matchers for deferred rematches, one per thread that
// completes one at a time, made on first need and reused.
using ExactMatcherPool = ObjectPool<FeatureMatcher>;

class ExactRematchFeatureMatcher : public FeatureMatcher {
 public:
  // `cascade` must support MatchPairsExact; `min_matches` > 0; `max_matches`
  // 0 (no upper bound) or above min_matches: then only pairs with fewer
  // cascade matches are matched again (CasHashOptions::
  // exact_rematch_max_matches). `counts` may
  // be null (the matcher then keeps its own). With a `pool`,
  // MatchPairsDeferred leaves the rematch to its caller (see above);
  // MatchPairs always rematches at once, from the cascade's descriptors.
  ExactRematchFeatureMatcher(std::unique_ptr<FeatureMatcher> cascade, size_t min_matches,
                             std::shared_ptr<ExactRematchCounts> counts = nullptr,
                             std::shared_ptr<ExactMatcherPool> pool = nullptr, size_t max_matches = 0);

  void AddImage(image_t image_id, const FeatureDescriptors& descriptors) override;
  void AddSharedImage(image_t image_id, std::shared_ptr<const FeatureDescriptors> descriptors) override;
  void RemoveImage(image_t image_id) override;
  std::vector<FeatureMatches> MatchPairs(const std::vector<ImagePair>& pairs) override;
  ChunkMatches MatchPairsDeferred(const std::vector<ImagePair>& pairs) override;
  // "<cascade>+exact-rematch"
  std::string Name() const override;
  // Guided matching (Ga-CasHash) goes to the cascade alone: the band filter
  // is its own screening.
  bool SupportsEpipolarGuidance() const override;
  std::vector<FeatureMatches> MatchPairsGuided(const std::vector<GuidedPair>& pairs, double max_distance) override;
  bool SupportsExactMatching() const override { return true; }
  std::vector<FeatureMatches> MatchPairsExact(const std::vector<ImagePair>& pairs) override;

  // Pairs matched so far, and of those matched again exactly.
  size_t pairs_matched() const { return counts_->pairs; }
  size_t pairs_rematched() const { return counts_->rematched; }

 private:
  // Indices of the pairs whose cascade matches reach min_matches (and stay
  // below max_matches where that is set).
  std::vector<size_t> PairsToRematch(const std::vector<FeatureMatches>& cascade_matches) const;

  std::unique_ptr<FeatureMatcher> cascade_;
  size_t min_matches_;
  size_t max_matches_;
  std::shared_ptr<ExactRematchCounts> counts_;
  std::shared_ptr<ExactMatcherPool> pool_;
};

}  // namespace cashash
