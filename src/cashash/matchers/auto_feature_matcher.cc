#include "cashash/matchers/auto_feature_matcher.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <stdexcept>
#include <utility>

#include "cashash/pipeline/thread_pool.h"

namespace cashash {
namespace {

std::string Milliseconds(double seconds) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.3f", 1000.0 * seconds);
  return text;
}

}  // namespace

AutoMatcherOptions CpuAutoMatcherOptions(const SiftMatchingOptions& sift) {
  AutoMatcherOptions options;
  options.min_batch_pairs = static_cast<size_t>(ResolveNumThreads(sift.num_threads));
  options.first_timed_call = 2;
  return options;
}

AutoMatcherOptions GpuAutoMatcherOptions() {
  AutoMatcherOptions options;
  options.warmup_pairs = 8;
  options.min_batch_pairs = 64;
  options.interleave_slice_pairs = 64;
  options.first_timed_call = 2;
  // Brute force searches the reverse direction over the named rows only
  // (1.7x faster): at 8,192 features its 512-pair round of far pairs took
  // under 10 ms on the H200, so the probe went on into the run's third chunk
  // with verification held back (auto 4-7 % behind the cascade forced). No verification shares the GPU while the probe runs,
  // so 5 ms of a 3x gap is far above the jitter.
  options.min_decisive_seconds = 0.005;
  // A close call (within 1.5x, batches short of min_probe_seconds) ends
  // after the 512-pair round: on the H200 at 2,048 features (cascade 0.002,
  // brute force 0.003 ms a pair) 4,096 timed pairs each held verification
  // back for a tenth of the run and made auto 15-20 % slower than either
  // backend forced; 960 pairs each in interleaved turns
  // measure a per-pair time well within that 1.5x.
  options.max_probe_pairs = 64 + 128 + 256 + 512;
  return options;
}

AutoFeatureMatcher::AutoFeatureMatcher(std::unique_ptr<FeatureMatcher> cascade,
                                       std::unique_ptr<FeatureMatcher> brute_force, AutoMatcherOptions options,
                                       std::function<void(const std::string&)> info)
    : cascade_(std::move(cascade)),
      brute_force_(std::move(brute_force)),
      options_(std::move(options)),
      info_(std::move(info)) {
  if (!cascade_ || !brute_force_) throw std::invalid_argument("AutoFeatureMatcher needs two backends");
  options_.min_batch_pairs = std::max<size_t>(1, options_.min_batch_pairs);
  options_.max_batch_pairs = std::max(options_.min_batch_pairs, options_.max_batch_pairs);
  warmup_left_ = options_.warmup_pairs;
  batch_ = options_.min_batch_pairs;
}

double AutoFeatureMatcher::Now() const {
  if (options_.now) return options_.now();
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

void AutoFeatureMatcher::AddImage(image_t image_id, const FeatureDescriptors& descriptors) {
  if (winner_ != nullptr) return winner_->AddImage(image_id, descriptors);
  cascade_->AddImage(image_id, descriptors);
  brute_force_->AddImage(image_id, descriptors);
  images_.insert(image_id);
}

void AutoFeatureMatcher::AddSharedImage(image_t image_id, std::shared_ptr<const FeatureDescriptors> descriptors) {
  if (winner_ != nullptr) return winner_->AddSharedImage(image_id, std::move(descriptors));
  cascade_->AddSharedImage(image_id, descriptors);
  brute_force_->AddSharedImage(image_id, descriptors);
  images_.insert(image_id);
}

void AutoFeatureMatcher::RemoveImage(image_t image_id) {
  if (winner_ != nullptr) return winner_->RemoveImage(image_id);
  cascade_->RemoveImage(image_id);
  brute_force_->RemoveImage(image_id);
  images_.erase(image_id);
}

double AutoFeatureMatcher::MatchSubset(FeatureMatcher* backend, const std::vector<ImagePair>& pairs,
                                       const std::vector<size_t>& indices, std::vector<FeatureMatches>* results) {
  if (indices.empty()) return 0.0;
  std::vector<ImagePair> subset;
  subset.reserve(indices.size());
  for (size_t i : indices) subset.push_back(pairs[i]);
  const double start = Now();
  std::vector<FeatureMatches> matched = backend->MatchPairs(subset);
  const double seconds = Now() - start;
  if (matched.size() != indices.size()) throw std::logic_error(backend->Name() + " returned a wrong number of results");
  for (size_t k = 0; k < indices.size(); ++k) (*results)[indices[k]] = std::move(matched[k]);
  return seconds;
}

size_t AutoFeatureMatcher::SlicesFor(size_t pairs_each) const {
  if (options_.interleave_slice_pairs == 0) return 1;
  return std::clamp<size_t>(pairs_each / options_.interleave_slice_pairs, 1,
                            std::max<size_t>(1, options_.max_interleaved_slices));
}

AutoFeatureMatcher::Turns AutoFeatureMatcher::SplitWindow(size_t next, size_t window) const {
  // Alternate pairs of the window, the same number to each backend; which
  // one goes first alternates by round. An odd last pair of a chunk goes to
  // the first one, untimed.
  Turns turns;
  turns.cascade_first = round_ % 2 == 0;
  for (size_t k = 0; k + 1 < window; k += 2) {
    turns.to_first.push_back(next + k);
    turns.to_second.push_back(next + k + 1);
  }
  if (window % 2 == 1) turns.extra.push_back(next + window - 1);
  return turns;
}

void AutoFeatureMatcher::MatchInTurns(Turns* turns, size_t slices, const std::vector<ImagePair>& pairs,
                                      std::vector<FeatureMatches>* results) {
  // Turns of equal slices, so that a load on the device that comes or goes
  // during the round falls on both backends.
  FeatureMatcher* first = turns->cascade_first ? cascade_.get() : brute_force_.get();
  FeatureMatcher* second = turns->cascade_first ? brute_force_.get() : cascade_.get();
  const std::vector<size_t>& to_first = turns->to_first;
  const std::vector<size_t>& to_second = turns->to_second;
  for (size_t slice = 0; slice < slices; ++slice) {
    const size_t begin = to_first.size() * slice / slices, end = to_first.size() * (slice + 1) / slices;
    const std::vector<size_t> part1(to_first.begin() + begin, to_first.begin() + end);
    const std::vector<size_t> part2(to_second.begin() + begin, to_second.begin() + end);
    turns->first_seconds += MatchSubset(first, pairs, part1, results);
    turns->second_seconds += MatchSubset(second, pairs, part2, results);
  }
  MatchSubset(first, pairs, turns->extra, results);
  (turns->cascade_first ? decision_.cascade_pairs : decision_.brute_force_pairs) +=
      to_first.size() + turns->extra.size();
  (turns->cascade_first ? decision_.brute_force_pairs : decision_.cascade_pairs) += to_second.size();
}

void AutoFeatureMatcher::CountRound(const Turns& turns, size_t slices) {
  pending_cascade_seconds_ += turns.cascade_first ? turns.first_seconds : turns.second_seconds;
  pending_brute_force_seconds_ += turns.cascade_first ? turns.second_seconds : turns.first_seconds;
  pending_pairs_ += turns.to_first.size();
  pending_slices_ += slices;
  if (pending_pairs_ < batch_) return;  // the round goes on in the next call
  const bool interleaved = options_.interleave_slice_pairs == 0 || pending_slices_ >= 2;
  pending_slices_ = 0;
  cascade_timing_.seconds = pending_cascade_seconds_;
  brute_force_timing_.seconds = pending_brute_force_seconds_;
  cascade_timing_.pairs = brute_force_timing_.pairs = pending_pairs_;
  cascade_timing_.timed_pairs += pending_pairs_;
  brute_force_timing_.timed_pairs += pending_pairs_;
  pending_cascade_seconds_ = pending_brute_force_seconds_ = 0;
  pending_pairs_ = 0;
  ++round_;
  batch_ = std::min(2 * batch_, options_.max_batch_pairs);
  if (interleaved) TryDecide();
}

std::vector<FeatureMatches> AutoFeatureMatcher::MatchPairs(const std::vector<ImagePair>& pairs) {
  if (winner_ != nullptr) return winner_->MatchPairs(pairs);
  ++calls_;
  // An untimed call (see first_timed_call) only takes the warm-up pairs,
  // so no round has begun when the first timed call comes.
  const bool timed_call = calls_ >= options_.first_timed_call;
  std::vector<FeatureMatches> results(pairs.size());
  size_t next = 0;
  while (winner_ == nullptr && next < pairs.size()) {
    const bool warmup = warmup_left_ > 0;
    if (!timed_call && !warmup) break;  // the rest of an untimed call: the cascade's
    // A round gives batch_ pairs to each backend, over several calls when
    // the chunks are small.
    const size_t want = warmup ? warmup_left_ : batch_ - pending_pairs_;
    const size_t window = std::min(pairs.size() - next, 2 * want);
    Turns turns = SplitWindow(next, window);
    const size_t slices = warmup ? 1 : SlicesFor(turns.to_first.size());
    MatchInTurns(&turns, slices, pairs, &results);
    next += window;
    if (warmup) {
      warmup_left_ = turns.to_second.size() >= warmup_left_ ? 0 : warmup_left_ - turns.to_second.size();
    } else {
      CountRound(turns, slices);
    }
  }
  if (next < pairs.size()) {
    std::vector<size_t> rest;
    for (size_t i = next; i < pairs.size(); ++i) rest.push_back(i);
    if (winner_ == nullptr) decision_.cascade_pairs += rest.size();
    MatchSubset(winner_ != nullptr ? winner_ : cascade_.get(), pairs, rest, &results);
  }
  return results;
}

void AutoFeatureMatcher::TryDecide() {
  if (cascade_timing_.pairs == 0 || brute_force_timing_.pairs == 0) return;
  const double cascade_per_pair = cascade_timing_.seconds / static_cast<double>(cascade_timing_.pairs);
  const double brute_per_pair = brute_force_timing_.seconds / static_cast<double>(brute_force_timing_.pairs);
  decision_.cascade_seconds_per_pair = cascade_per_pair;
  decision_.brute_force_seconds_per_pair = brute_per_pair;
  // Ties go to the cascade.
  const bool cascade_faster = cascade_per_pair <= brute_per_pair;
  const Timing& slow = cascade_faster ? brute_force_timing_ : cascade_timing_;
  const Timing& fast = cascade_faster ? cascade_timing_ : brute_force_timing_;
  const double slow_per_pair = std::max(cascade_per_pair, brute_per_pair);
  const double fast_per_pair = std::min(cascade_per_pair, brute_per_pair);
  const bool slow_long = slow.seconds >= options_.min_probe_seconds;
  const bool clear = slow_long && slow_per_pair >= options_.clear_ratio * fast_per_pair;
  const bool decisive =
      slow.seconds >= options_.min_decisive_seconds && slow_per_pair >= options_.decisive_ratio * fast_per_pair;
  const bool both_long = slow_long && fast.seconds >= options_.min_probe_seconds;
  const bool enough = std::min(cascade_timing_.timed_pairs, brute_force_timing_.timed_pairs) >= options_.max_probe_pairs;
  if (clear || decisive || both_long || enough) Decide(cascade_faster, "measured");
}

void AutoFeatureMatcher::Decide(bool cascade, const std::string& reason) {
  std::unique_ptr<FeatureMatcher>& keep = cascade ? cascade_ : brute_force_;
  std::unique_ptr<FeatureMatcher>& drop = cascade ? brute_force_ : cascade_;
  const std::string cascade_name = cascade_->Name(), brute_force_name = brute_force_->Name();
  for (image_t image_id : images_) drop->RemoveImage(image_id);
  images_.clear();
  drop.reset();
  winner_ = keep.get();
  decision_.decided = true;
  decision_.cascade_won = cascade;
  decision_.winner = winner_->Name();
  decision_.reason = reason;
  if (!info_) return;
  if (reason == "measured") {
    info_("Matcher auto: " + cascade_name + " " + Milliseconds(decision_.cascade_seconds_per_pair) +
          " ms per pair, " + brute_force_name + " " + Milliseconds(decision_.brute_force_seconds_per_pair) +
          " ms per pair (timed on " + std::to_string(cascade_timing_.pairs) + " pairs each); using " +
          decision_.winner);
  } else {
    info_("Matcher auto: " + reason + " needs the cascade; using " + decision_.winner);
  }
}

std::string AutoFeatureMatcher::Name() const {
  if (winner_ != nullptr) return winner_->Name();
  return "auto(" + cascade_->Name() + "|" + brute_force_->Name() + ")";
}

bool AutoFeatureMatcher::SupportsEpipolarGuidance() const {
  return winner_ != nullptr ? winner_->SupportsEpipolarGuidance() : cascade_->SupportsEpipolarGuidance();
}

ChunkMatches AutoFeatureMatcher::MatchPairsDeferred(const std::vector<ImagePair>& pairs) {
  if (winner_ != nullptr) return winner_->MatchPairsDeferred(pairs);
  return ChunkMatches{MatchPairs(pairs), nullptr};
}

std::vector<FeatureMatches> AutoFeatureMatcher::MatchPairsGuided(const std::vector<GuidedPair>& pairs,
                                                                 double max_distance) {
  if (winner_ == nullptr) Decide(true, "guided matching");
  return winner_->MatchPairsGuided(pairs, max_distance);
}

}  // namespace cashash
