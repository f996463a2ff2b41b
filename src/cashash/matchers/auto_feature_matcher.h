// --CasHash.matcher auto: one cascade and one brute-force backend behind one
// FeatureMatcher. On the run's first pairs both are timed on disjoint
// samples of the same chunk (alternate pairs, in rounds of growing size,
// both backends the same number of pairs per round); as soon as one is
// clearly faster per pair, or both have been timed long enough, the faster
// is kept, the other one's images are removed and it is destroyed, and
// every later pair goes to the winner. Each pair is matched by exactly one
// backend, and results come back in the callers' order.
//
// Brute force is exact, so at equal or better quality the only question is
// speed: on small images (or a GPU that is idle between short launches)
// brute force can win, on large ones the cascade does by a growing margin.
// Guided matching needs the cascade: MatchPairsGuided decides for it.
#pragma once

#include <cstddef>
#include <functional>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "cashash/matchers/feature_matcher.h"

namespace cashash {

struct AutoMatcherOptions {
  // Pairs per backend matched first without timing them (GPU: lazy module
  // loading and first allocations). 0 on the CPU.
  size_t warmup_pairs = 0;
  // Pairs per backend in the first timed round; each round doubles it, up
  // to max_batch_pairs. On the CPU: the worker threads (one pair each).
  size_t min_batch_pairs = 1;
  size_t max_batch_pairs = 1024;
  // A round decides when the slower backend's batch took at least
  // min_probe_seconds and is clear_ratio times slower per pair, or when
  // both batches took at least min_probe_seconds (the faster per pair wins).
  double min_probe_seconds = 0.05;
  double clear_ratio = 1.5;
  // A round also decides when the slower backend's batch took at least
  // min_decisive_seconds and is decisive_ratio times slower per pair: every
  // probe pair costs the slower backend's time, (ratio - 1) pairs' worth
  // more than the winner's, while noise of a few milliseconds (verification
  // sharing the GPU) cannot turn a 3x gap round. On the H200 at 8,192
  // features this decides after the 256-pair round instead of the
  // 1,024-pair one.
  double min_decisive_seconds = 0.01;
  double decisive_ratio = 3.0;
  // When > 0, each backend's share of a round is matched in slices of at
  // least this many pairs (at most max_interleaved_slices), the two
  // backends taking turns, and only a round of two slices or more (or
  // spread over several calls) may decide. Verification of the chunk before
  // shares the GPU with the probe and its load changes within a round: run
  // back to back, the backend that goes first can take all of it (on the
  // H200 one 64-pair round timed the cascade 4x slower than brute force at
  // 16,384 features, where it had been 8x faster unloaded). 0 on the CPU,
  // where rounds are one pair per thread.
  size_t interleave_slice_pairs = 0;
  size_t max_interleaved_slices = 4;
  // Timed pairs per backend after which the faster so far wins anyway.
  size_t max_probe_pairs = 4096;
  // The MatchPairs call (chunk) from which on timings count: in earlier
  // calls each backend takes its warm-up pairs and the cascade the rest,
  // untimed. Runs give 2: an exhaustive run's
  // first chunk is one block against itself, mostly neighbouring images,
  // where the cascade (cross-check queries and thin-list lookups for each
  // match) is slowest, while most of a run's pairs do not overlap. At
  // 16,384 features the first chunk made brute force look 1.2x faster
  // while the cascade was 1.9x faster over the whole run. The untimed
  // pairs go to the cascade because they decide nothing: where brute force
  // wins, both cost microseconds a pair, and where the cascade does, brute
  // force's half of that chunk cost the H200 about 60 ms at 16,384 features.
  size_t first_timed_call = 1;
  // Seconds of a monotonic clock; the default is std::chrono::steady_clock.
  // Tests pass a fake one.
  std::function<double()> now;
};

// The probe settings for CPU backends running `sift.num_threads` threads
// (one pair per thread in the first round) and for GPU backends (a warm-up
// of a few pairs, then rounds from 64 pairs).
AutoMatcherOptions CpuAutoMatcherOptions(const SiftMatchingOptions& sift);
AutoMatcherOptions GpuAutoMatcherOptions();

struct AutoMatcherDecision {
  bool decided = false;
  bool cascade_won = false;
  std::string winner;  // Name() of the winner
  std::string reason;  // "measured", "guided matching"
  // Of the latest timed batch of each backend.
  double cascade_seconds_per_pair = 0, brute_force_seconds_per_pair = 0;
  // Pairs each backend matched while both were kept (warm-up included).
  size_t cascade_pairs = 0, brute_force_pairs = 0;
};

class AutoFeatureMatcher : public FeatureMatcher {
 public:
  // `info` receives the decision as one line for the log (may be empty).
  AutoFeatureMatcher(std::unique_ptr<FeatureMatcher> cascade, std::unique_ptr<FeatureMatcher> brute_force,
                     AutoMatcherOptions options, std::function<void(const std::string&)> info);

  void AddImage(image_t image_id, const FeatureDescriptors& descriptors) override;
  void AddSharedImage(image_t image_id, std::shared_ptr<const FeatureDescriptors> descriptors) override;
  void RemoveImage(image_t image_id) override;
  std::vector<FeatureMatches> MatchPairs(const std::vector<ImagePair>& pairs) override;
  // The winner's, once chosen; while timing, MatchPairs (nothing deferred:
  // each backend's time includes all its work).
  ChunkMatches MatchPairsDeferred(const std::vector<ImagePair>& pairs) override;
  // The winner's name once decided; "auto(cascade name|brute-force name)" before.
  std::string Name() const override;
  bool ChoosingBackend() const override { return winner_ == nullptr; }
  bool SupportsEpipolarGuidance() const override;
  std::vector<FeatureMatches> MatchPairsGuided(const std::vector<GuidedPair>& pairs, double max_distance) override;

  const AutoMatcherDecision& decision() const { return decision_; }

 private:
  struct Timing {
    double seconds = 0;  // latest timed batch
    size_t pairs = 0;
    size_t timed_pairs = 0;  // all timed batches
  };
  // Matches `pairs[indices]` on `backend` into `results`; returns seconds.
  double MatchSubset(FeatureMatcher* backend, const std::vector<ImagePair>& pairs,
                     const std::vector<size_t>& indices, std::vector<FeatureMatches>* results);
  // One round's (or warm-up's) share of a call: whether the cascade goes
  // first, the pairs (indices into the call) each takes, and their times.
  struct Turns {
    bool cascade_first = true;
    std::vector<size_t> to_first, to_second, extra;
    double first_seconds = 0, second_seconds = 0;
  };
  // Slices each of `to_first` and `to_second` is matched in (see
  // interleave_slice_pairs).
  size_t SlicesFor(size_t pairs_each) const;
  Turns SplitWindow(size_t next, size_t window) const;
  void MatchInTurns(Turns* turns, size_t slices, const std::vector<ImagePair>& pairs,
                    std::vector<FeatureMatches>* results);
  // Adds a timed share to the round; a full round updates the timings and
  // may decide.
  void CountRound(const Turns& turns, size_t slices);
  void TryDecide();
  void Decide(bool cascade, const std::string& reason);
  double Now() const;

  std::unique_ptr<FeatureMatcher> cascade_, brute_force_;
  FeatureMatcher* winner_ = nullptr;
  AutoMatcherOptions options_;
  std::function<void(const std::string&)> info_;
  std::set<image_t> images_;  // added to both while undecided
  size_t calls_ = 0;
  size_t warmup_left_ = 0;
  size_t batch_ = 1;
  size_t round_ = 0;
  // The current round so far (it may span several MatchPairs calls).
  size_t pending_pairs_ = 0;
  size_t pending_slices_ = 0;  // turns each backend took in the round
  double pending_cascade_seconds_ = 0, pending_brute_force_seconds_ = 0;
  Timing cascade_timing_, brute_force_timing_;
  AutoMatcherDecision decision_;
};

}  // namespace cashash
