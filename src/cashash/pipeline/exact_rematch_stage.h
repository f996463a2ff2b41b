// The exact rematch, one stage of the pipeline: the cascade screens, exact
// matching decides. Every pair is matched by the cascade; a pair that keeps
// at least `min_matches` matches (one that may verify), and fewer than
// `max_matches` where that is set, is matched again exactly by the same
// backend from the descriptors it already holds (ExactMatcher), and the
// exact matches replace the cascade's.
//
// Why: the cascade's first level misses true matches whose hash bits differ
// in every table. On photographs with changing light and viewpoint that is
// several percent of them (docs/cascade_parameters.md), and those are the
// pairs where few matches decide whether a pair verifies and how many
// inliers it keeps. The pairs that can verify are a small share of an
// exhaustive run's pairs, so matching them exactly costs little next to
// screening all pairs with the cascade, and their raw matches, inliers and
// two-view geometry are exact matching's, as COLMAP's. Pairs below the
// threshold keep the cascade's matches: with fewer than min_num_inliers (15)
// of them RANSAC is not run at all.
//
// Where it runs is part of the policy (ExactRematchPolicy::where, decided
// once per run by ResolveRun):
// - on the matching thread, right after the chunk's cascade;
// - on a verification thread, before the chunk is verified: the matching
//   thread holds the pairs' images (MatchingBackend::HoldForExact: the GPU
//   cascade lends the descriptors it holds on the device) and goes on with
//   the next chunk's cascade while the rematch runs. Held images that find
//   no room on the device (DeviceMemoryError) are matched by brute-force
//   matchers from a pool instead, fed with the chunk's descriptors, whose
//   GPU matchers go on on the CPU when the device has no room for them
//   either (CreateFallbackFeatureMatcher): out of memory in the rematch
//   costs time, never the run.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "cashash/base/object_pool.h"
#include "cashash/matchers/exact_matcher.h"

namespace cashash {

// Where a run's exact rematch runs.
enum class RematchPlace {
  kNowhere,             // no rematch: the cascade's matches are kept
  kMatchingThread,      // right after the chunk's cascade
  kVerificationThread,  // before the chunk is verified, from held images
};

// "nowhere", "matching thread", "verification thread".
const char* RematchPlaceName(RematchPlace place);

// The one policy of the exact rematch.
struct ExactRematchPolicy {
  // Fewest cascade matches of a pair that is matched again; > 0 unless
  // where is kNowhere.
  size_t min_matches = 0;
  // 0: no upper bound. Else above min_matches: only pairs with fewer
  // cascade matches are matched again (CasHashOptions::
  // exact_rematch_max_matches, the CPU's window).
  size_t max_matches = 0;
  RematchPlace where = RematchPlace::kNowhere;

  bool enabled() const { return where != RematchPlace::kNowhere; }
  // Whether a pair with `cascade_matches` matches is matched again.
  bool Selects(size_t cascade_matches) const;
  // "" when valid, else what is wrong.
  std::string Check() const;
};

// What a run's rematching did, for its log.
struct ExactRematchCounts {
  std::atomic<size_t> pairs{0};      // matched by the cascade
  std::atomic<size_t> rematched{0};  // of those, matched again exactly
  std::atomic<int64_t> exact_us{0};  // wall time of the exact matching
  // Held images that found no room on the device (DeviceMemoryError) and
  // were matched by the pool's matchers instead.
  std::atomic<size_t> held_without_memory{0};
};

// Brute-force matchers for held images that find no device memory, one per
// thread that completes one at a time, made on first need and reused.
using ExactMatcherPool = ObjectPool<FeatureMatcher>;

// A chunk's pairs whose rematch waits for a verification thread.
struct PendingRematch {
  std::vector<size_t> indices;  // positions in the chunk's pairs
  std::vector<ImagePair> pairs;
  std::unique_ptr<ExactMatcher> held;  // their images, held by the backend

  bool empty() const { return indices.empty(); }
};

class ExactRematchStage {
 public:
  // The chunk's descriptors of an image, still held by the pipeline.
  using DescriptorLookup = std::function<std::shared_ptr<const FeatureDescriptors>(image_t)>;

  // `backend`: the cascade the pipeline adds its images to (not owned; the
  // images reach it through any wrappers). `pool` (may be null: the error
  // then stops the run) serves held images without device memory.
  // Throws std::invalid_argument for an invalid policy or, with a policy
  // that rematches, no backend.
  ExactRematchStage(const ExactRematchPolicy& policy, MatchingBackend* backend,
                    std::shared_ptr<ExactMatcherPool> pool = nullptr);

  const ExactRematchPolicy& policy() const { return policy_; }
  const ExactRematchCounts& counts() const { return counts_; }

  // On the matching thread, right after the cascade matched `pairs`
  // (`matches` in their order): on the matching thread the selected pairs'
  // exact matches replace the cascade's now; on a verification thread their
  // images are held and returned, for Complete.
  PendingRematch AfterMatching(const std::vector<ImagePair>& pairs, std::vector<FeatureMatches>* matches);

  // On any thread, once per pending rematch: its exact matches replace the
  // entries of `matches` (the chunk's, in its pair order). Lets go of the
  // held images.
  void Complete(PendingRematch* pending, const DescriptorLookup& descriptors, std::vector<FeatureMatches>* matches);

 private:
  std::vector<FeatureMatches> MatchWithPool(const std::vector<ImagePair>& pairs, const DescriptorLookup& descriptors);

  const ExactRematchPolicy policy_;
  MatchingBackend* backend_;
  std::shared_ptr<ExactMatcherPool> pool_;
  ExactRematchCounts counts_;
};

}  // namespace cashash
