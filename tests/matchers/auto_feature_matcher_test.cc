// --CasHash.matcher auto (auto_feature_matcher.h) with fake backends whose
// speed a fake clock sets: the faster one is kept whichever it is, every
// pair is matched once by exactly one backend, in the callers' order, the
// loser's images are removed and it is destroyed, guided matching keeps the
// cascade, and an explicit matcher type gets no wrapper.
#include "cashash/matchers/auto_feature_matcher.h"

#include <algorithm>
#include <map>
#include <memory>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "synthetic_sift.h"

namespace cashash {
namespace {

// What a fake backend did; outlives it.
struct Record {
  std::set<image_t> images;
  std::vector<ImagePair> matched;
  size_t calls = 0;
  size_t deferred_calls = 0;  // MatchPairsDeferred
  bool destroyed = false;
};

// Deferred work that leaves the matches as they are.
class NothingLeft : public DeferredMatching {
 public:
  void Complete(const DescriptorLookup&, std::vector<FeatureMatches>*) override {}
};

// Answers pair (a, b) with the single match (a, b) and advances the clock
// by `seconds_per_pair` per pair (plus `seconds_per_call`).
class FakeMatcher : public FeatureMatcher {
 public:
  FakeMatcher(std::string name, double* clock, double seconds_per_pair, double seconds_per_call, Record* record,
              bool guided = false)
      : name_(std::move(name)),
        clock_(clock),
        per_pair_(seconds_per_pair),
        per_call_(seconds_per_call),
        record_(record),
        guided_(guided) {}
  ~FakeMatcher() override { record_->destroyed = true; }
  void AddImage(image_t id, const FeatureDescriptors&) override { record_->images.insert(id); }
  void RemoveImage(image_t id) override { record_->images.erase(id); }
  // Calls that start before *busy_until take busy_factor times as long (the
  // GPU shared with a verification that ends then).
  void SetBusy(const double* busy_until, double busy_factor) {
    busy_until_ = busy_until;
    busy_factor_ = busy_factor;
  }
  std::vector<FeatureMatches> MatchPairs(const std::vector<ImagePair>& pairs) override {
    ++record_->calls;
    const double factor = busy_until_ != nullptr && *clock_ < *busy_until_ ? busy_factor_ : 1.0;
    *clock_ += factor * (per_call_ + per_pair_ * static_cast<double>(pairs.size()));
    std::vector<FeatureMatches> results;
    for (const ImagePair& pair : pairs) {
      if (!record_->images.count(pair.first) || !record_->images.count(pair.second)) {
        throw std::out_of_range(name_ + ": image not added");
      }
      record_->matched.push_back(pair);
      results.push_back({FeatureMatch{static_cast<uint32_t>(pair.first), static_cast<uint32_t>(pair.second)}});
    }
    return results;
  }
  // MatchPairs, and a deferred part (as the GPU's exact rematch leaves).
  ChunkMatches MatchPairsDeferred(const std::vector<ImagePair>& pairs) override {
    ++record_->deferred_calls;
    return ChunkMatches{MatchPairs(pairs), std::make_unique<NothingLeft>()};
  }
  std::string Name() const override { return name_; }
  bool SupportsEpipolarGuidance() const override { return guided_; }
  std::vector<FeatureMatches> MatchPairsGuided(const std::vector<GuidedPair>& pairs, double) override {
    if (!guided_) return FeatureMatcher::MatchPairsGuided({}, 0);
    std::vector<ImagePair> plain;
    for (const GuidedPair& p : pairs) plain.push_back(p.pair);
    return MatchPairs(plain);
  }

 private:
  std::string name_;
  double* clock_;
  double per_pair_, per_call_;
  Record* record_;
  bool guided_;
  const double* busy_until_ = nullptr;
  double busy_factor_ = 1.0;
};

struct Harness {
  double clock = 0;
  Record cascade, brute_force;
  std::vector<std::string> log;
  std::unique_ptr<AutoFeatureMatcher> matcher;
  double busy_until = -1;  // see FakeMatcher::SetBusy

  Harness(double cascade_per_pair, double brute_force_per_pair, AutoMatcherOptions options = AutoMatcherOptions(),
          double per_call = 0, double busy_factor = 1.0) {
    options.now = [this] { return clock; };
    auto fake_cascade = std::make_unique<FakeMatcher>("fake-cascade", &clock, cascade_per_pair, per_call, &cascade, true);
    auto fake_brute_force =
        std::make_unique<FakeMatcher>("fake-bruteforce", &clock, brute_force_per_pair, per_call, &brute_force);
    fake_cascade->SetBusy(&busy_until, busy_factor);
    fake_brute_force->SetBusy(&busy_until, busy_factor);
    matcher = std::make_unique<AutoFeatureMatcher>(std::move(fake_cascade), std::move(fake_brute_force), options,
                                                   [this](const std::string& text) { log.push_back(text); });
  }
};

// The H200's times per pair at 8,192 features.
constexpr double kGpuCascadePerPair = 0.000015, kGpuBruteForcePerPair = 0.000051;

// The GPU's rounds (64 pairs first, then doubling), each backend's share in
// slices of `slice_pairs` (0: back to back).
AutoMatcherOptions GpuRounds(size_t slice_pairs) {
  AutoMatcherOptions options;
  options.min_batch_pairs = 64;
  options.interleave_slice_pairs = slice_pairs;
  return options;
}

std::vector<ImagePair> AllPairs(int first, int last) {
  std::vector<ImagePair> pairs;
  for (int i = first; i < last; ++i)
    for (int j = i + 1; j < last; ++j) pairs.emplace_back(image_t(i), image_t(j));
  return pairs;
}

// Runs `pairs` through the matcher in chunks of `chunk`, adding images 0..n-1
// first; checks the answers' order and that every pair was matched once by
// exactly one backend.
void RunChunks(Harness* h, int num_images, size_t chunk) {
  FeatureDescriptors none;
  for (int i = 0; i < num_images; ++i) h->matcher->AddImage(image_t(i), none);
  const std::vector<ImagePair> pairs = AllPairs(0, num_images);
  for (size_t begin = 0; begin < pairs.size(); begin += chunk) {
    const std::vector<ImagePair> part(pairs.begin() + begin, pairs.begin() + std::min(pairs.size(), begin + chunk));
    const std::vector<FeatureMatches> results = h->matcher->MatchPairs(part);
    ASSERT_EQ(results.size(), part.size());
    for (size_t k = 0; k < part.size(); ++k) {
      ASSERT_EQ(results[k].size(), 1u);
      EXPECT_EQ(results[k][0].point2D_idx1, part[k].first);
      EXPECT_EQ(results[k][0].point2D_idx2, part[k].second);
    }
  }
  std::map<std::pair<image_t, image_t>, int> times;
  for (const ImagePair& p : h->cascade.matched) ++times[{p.first, p.second}];
  for (const ImagePair& p : h->brute_force.matched) ++times[{p.first, p.second}];
  EXPECT_EQ(times.size(), pairs.size());
  for (const auto& [pair, count] : times) EXPECT_EQ(count, 1) << pair.first << "-" << pair.second;
}

TEST(AutoFeatureMatcher, KeepsTheCascadeWhenItIsFaster) {
  Harness h(0.001, 0.02);  // brute force 20x slower per pair
  RunChunks(&h, 40, 300);
  ASSERT_TRUE(h.matcher->decision().decided);
  EXPECT_TRUE(h.matcher->decision().cascade_won);
  EXPECT_EQ(h.matcher->Name(), "fake-cascade");
  EXPECT_TRUE(h.brute_force.destroyed);
  EXPECT_TRUE(h.brute_force.images.empty());  // freed before destruction
  EXPECT_FALSE(h.cascade.destroyed);
  // Brute force saw only a small probe.
  EXPECT_LT(h.brute_force.matched.size(), 100u);
  EXPECT_GT(h.cascade.matched.size(), 650u);
  EXPECT_EQ(h.matcher->decision().winner, "fake-cascade");
  EXPECT_EQ(h.matcher->decision().reason, "measured");
  EXPECT_NEAR(h.matcher->decision().cascade_seconds_per_pair, 0.001, 1e-9);
  EXPECT_NEAR(h.matcher->decision().brute_force_seconds_per_pair, 0.02, 1e-9);
  EXPECT_EQ(h.log.size(), 1u);  // the decision is reported once
}

// While timing, each backend's time must include all its work: nothing is
// deferred. Once decided, the winner's deferred work is passed on.
TEST(AutoFeatureMatcher, DefersNothingWhileTimingAndThenWhatTheWinnerDefers) {
  Harness h(0.001, 0.02);
  FeatureDescriptors none;
  for (int i = 0; i < 40; ++i) h.matcher->AddImage(image_t(i), none);
  const std::vector<ImagePair> pairs = AllPairs(0, 40);
  size_t deferred_chunks = 0, chunks = 0, undecided_chunks = 0;
  for (size_t begin = 0; begin < pairs.size(); begin += 100) {
    const bool decided_before = h.matcher->decision().decided;
    const std::vector<ImagePair> part(pairs.begin() + begin, pairs.begin() + std::min(pairs.size(), begin + 100));
    ChunkMatches matched = h.matcher->MatchPairsDeferred(part);
    ASSERT_EQ(matched.matches.size(), part.size());
    ++chunks;
    if (!decided_before) {
      ++undecided_chunks;
      EXPECT_EQ(matched.deferred, nullptr) << "chunk " << chunks;
    }
    deferred_chunks += matched.deferred != nullptr;
  }
  ASSERT_TRUE(h.matcher->decision().cascade_won);
  EXPECT_GE(undecided_chunks, 1u);
  EXPECT_EQ(deferred_chunks, chunks - undecided_chunks);
  EXPECT_EQ(h.cascade.deferred_calls, deferred_chunks);
  EXPECT_EQ(h.brute_force.deferred_calls, 0u);
}

TEST(AutoFeatureMatcher, KeepsBruteForceWhenItIsFaster) {
  Harness h(0.03, 0.01);
  RunChunks(&h, 40, 300);
  ASSERT_TRUE(h.matcher->decision().decided);
  EXPECT_FALSE(h.matcher->decision().cascade_won);
  EXPECT_EQ(h.matcher->Name(), "fake-bruteforce");
  EXPECT_TRUE(h.cascade.destroyed);
  EXPECT_TRUE(h.cascade.images.empty());
  EXPECT_GT(h.brute_force.matched.size(), 650u);
  // Images added after the decision go to the winner alone.
  FeatureDescriptors none;
  h.matcher->AddImage(100, none);
  EXPECT_TRUE(h.brute_force.images.count(100));
  h.matcher->RemoveImage(100);
  EXPECT_FALSE(h.brute_force.images.count(100));
}

TEST(AutoFeatureMatcher, CloseCallsAreDecidedOnLongerSamplesAndPickTheFaster) {
  // 10 % apart: not clear after one round; decided once both batches are
  // long enough, for the faster one, both ways round.
  for (const bool cascade_faster : {true, false}) {
    AutoMatcherOptions options;
    options.min_batch_pairs = 2;
    Harness h(cascade_faster ? 0.0010 : 0.0011, cascade_faster ? 0.0011 : 0.0010, options);
    RunChunks(&h, 80, 1000);
    ASSERT_TRUE(h.matcher->decision().decided);
    EXPECT_EQ(h.matcher->decision().cascade_won, cascade_faster);
    // The batch that decided took at least min_probe_seconds on each side.
    const double batch = 0.05 / 0.001;
    EXPECT_GE(static_cast<double>(std::min(h.cascade.matched.size(), h.brute_force.matched.size())), batch * 0.9);
  }
}

TEST(AutoFeatureMatcher, ADecisiveGapEndsTheProbeOnAShortBatch) {
  // The H200's figures at 8,192 features: cascade 0.015 ms per pair, brute
  // force 0.051 ms (3.4x). Rounds of 64, 128 and 256 pairs: the 256-pair
  // round's 13 ms of brute force passes min_decisive_seconds, so the probe
  // stops there, long before min_probe_seconds.
  Harness h(kGpuCascadePerPair, kGpuBruteForcePerPair, GpuRounds(0));
  RunChunks(&h, 80, 2500);
  ASSERT_TRUE(h.matcher->decision().decided);
  EXPECT_TRUE(h.matcher->decision().cascade_won);
  EXPECT_EQ(h.brute_force.matched.size(), 64u + 128u + 256u);
  // A 2x gap is not decisive: the probe goes on until min_probe_seconds.
  Harness close(0.000025, kGpuBruteForcePerPair, GpuRounds(0));
  RunChunks(&close, 100, 2500);
  ASSERT_TRUE(close.matcher->decision().decided);
  EXPECT_TRUE(close.matcher->decision().cascade_won);
  EXPECT_EQ(close.brute_force.matched.size(), 64u + 128u + 256u + 512u + 1024u);
}

// With the GPU's settings, the probe decided for the cascade after the
// round of `round_pairs` pairs each: brute force matched its 8 warm-up
// pairs and its share of every round up to that one (64, 128, ...), and at
// most the odd last pair of a chunk besides.
void ExpectCascadeDecidedAfterRound(const Harness& h, size_t round_pairs) {
  ASSERT_TRUE(h.matcher->decision().decided);
  EXPECT_TRUE(h.matcher->decision().cascade_won);
  size_t brute_force_pairs = 8;
  for (size_t round = 64; round <= round_pairs; round *= 2) brute_force_pairs += round;
  EXPECT_GE(h.brute_force.matched.size(), brute_force_pairs);
  EXPECT_LE(h.brute_force.matched.size(), brute_force_pairs + 1);
}

TEST(AutoFeatureMatcher, TheGpuProbeIsShortForADecisiveGapAndForACloseCall) {
  // The H200 at 8,192 features once brute force searched the reverse
  // direction over the named rows only: cascade 0.006 ms,
  // brute force 0.028 ms per pair (4.7x). With the GPU's settings the
  // 256-pair round's 7.2 ms of brute force decide, in the second chunk.
  Harness h(0.000006, 0.000028, GpuAutoMatcherOptions());
  RunChunks(&h, 80, 1225);
  ASSERT_NO_FATAL_FAILURE(ExpectCascadeDecidedAfterRound(h, 256));
  // Brute force matched its 8 warm-up pairs of the untimed first chunk (the
  // cascade the rest of it) and its share of the rounds of 64, 128 and 256.
  EXPECT_EQ(h.brute_force.matched.size(), 8u + 64u + 128u + 256u);
  EXPECT_EQ(h.matcher->decision().cascade_pairs, 1225u - 8u + 64u + 128u + 256u);
  // With the 10 ms of before, the 512-pair round, which reaches into the
  // third chunk.
  AutoMatcherOptions before = GpuAutoMatcherOptions();
  before.min_decisive_seconds = 0.01;
  Harness old(0.000006, 0.000028, before);
  RunChunks(&old, 80, 1225);
  ASSERT_NO_FATAL_FAILURE(ExpectCascadeDecidedAfterRound(old, 512));
  EXPECT_GT(old.brute_force.matched.size(), h.brute_force.matched.size() + 400);
  // A close call (2,048 features on the H200: cascade 0.002 ms, brute
  // force 0.003 ms per pair) ends after the 512-pair round, for the faster.
  Harness close(0.000002, 0.000003, GpuAutoMatcherOptions());
  RunChunks(&close, 80, 1225);
  ASSERT_NO_FATAL_FAILURE(ExpectCascadeDecidedAfterRound(close, 512));
}

TEST(AutoFeatureMatcher, ALoadThatEndsMidRoundDoesNotDecide) {
  // The GPU's settings (rounds from 64 pairs, slices of 64). The device is
  // 20x slower until 19 ms: the cascade's first 64 pairs take 19.2 ms there,
  // brute force's, right after, its unloaded 3.3 ms, so that round alone
  // says brute force is 5.9x faster. It is one slice each and does not
  // decide; the next round, two slices each, does, for the cascade.
  Harness h(kGpuCascadePerPair, kGpuBruteForcePerPair, GpuRounds(64), 0, 20.0);
  h.busy_until = 0.019;
  RunChunks(&h, 80, 2500);
  ASSERT_TRUE(h.matcher->decision().decided);
  EXPECT_TRUE(h.matcher->decision().cascade_won);
  // Without turns the first round decides, wrongly.
  Harness once(kGpuCascadePerPair, kGpuBruteForcePerPair, GpuRounds(0), 0, 20.0);
  once.busy_until = 0.019;
  RunChunks(&once, 80, 2500);
  ASSERT_TRUE(once.matcher->decision().decided);
  EXPECT_FALSE(once.matcher->decision().cascade_won);
}

TEST(AutoFeatureMatcher, TurnsSplitARoundIntoEqualSlices) {
  // Rounds of 64, 128, 256 pairs: 1, 2 and 4 slices a backend.
  Harness h(kGpuCascadePerPair, kGpuBruteForcePerPair, GpuRounds(64));
  RunChunks(&h, 80, 2500);
  ASSERT_TRUE(h.matcher->decision().decided);
  EXPECT_EQ(h.brute_force.matched.size(), 64u + 128u + 256u);
  EXPECT_EQ(h.brute_force.calls, 1u + 2u + 4u);
  EXPECT_EQ(h.cascade.calls, 1u + 2u + 4u + 2u);  // and the rest of both chunks
}

TEST(AutoFeatureMatcher, FixedCostPerCallDoesNotFavourEither) {
  // Both pay 5 ms per call; brute force is 3x slower per pair. Equal batch
  // sizes make the per-call cost the same on both sides.
  Harness h(0.0002, 0.0006, AutoMatcherOptions(), 0.005);
  RunChunks(&h, 60, 2000);
  ASSERT_TRUE(h.matcher->decision().decided);
  EXPECT_TRUE(h.matcher->decision().cascade_won);
}

TEST(AutoFeatureMatcher, ProbeGoesOnOverSeveralChunksAndEachPairIsMatchedOnce) {
  // Chunks of 3 pairs (an odd last pair each time), slow clock: the probe
  // spans many calls.
  AutoMatcherOptions options;
  options.min_batch_pairs = 4;
  Harness h(0.001, 0.003, options);
  RunChunks(&h, 30, 3);
  ASSERT_TRUE(h.matcher->decision().decided);
  EXPECT_TRUE(h.matcher->decision().cascade_won);
}

TEST(AutoFeatureMatcher, WarmupPairsAreMatchedButNotTimed) {
  AutoMatcherOptions options;
  options.warmup_pairs = 8;
  options.min_batch_pairs = 16;
  Harness h(0.001, 0.02, options);
  RunChunks(&h, 30, 435);
  ASSERT_TRUE(h.matcher->decision().decided);
  EXPECT_TRUE(h.matcher->decision().cascade_won);
  // Warm-up 8 + one timed round of 16 for brute force.
  EXPECT_EQ(h.brute_force.matched.size(), 24u);
  EXPECT_EQ(h.matcher->decision().brute_force_pairs, 24u);
}

TEST(AutoFeatureMatcher, OnePairGoesToTheCascade) {
  // cashash.match and MatchImagePair match one pair: no probe is possible,
  // the cascade answers it and nothing is decided.
  Harness h(0.001, 0.0001);
  FeatureDescriptors none;
  h.matcher->AddImage(0, none);
  h.matcher->AddImage(1, none);
  const auto results = h.matcher->MatchPairs({{0, 1}});
  ASSERT_EQ(results.size(), 1u);
  EXPECT_EQ(h.cascade.matched.size(), 1u);
  EXPECT_TRUE(h.brute_force.matched.empty());
  EXPECT_FALSE(h.matcher->decision().decided);
  EXPECT_EQ(h.matcher->Name(), "auto(fake-cascade|fake-bruteforce)");
}

TEST(AutoFeatureMatcher, GuidedMatchingKeepsTheCascade) {
  Harness h(0.01, 0.0001);  // brute force faster, but guidance needs the cascade
  EXPECT_TRUE(h.matcher->SupportsEpipolarGuidance());
  FeatureDescriptors none;
  h.matcher->AddImage(0, none);
  h.matcher->AddImage(1, none);
  GuidedPair pair;
  pair.pair = ImagePair(0, 1);
  const auto results = h.matcher->MatchPairsGuided({pair}, 4.0);
  ASSERT_EQ(results.size(), 1u);
  EXPECT_TRUE(h.matcher->decision().cascade_won);
  EXPECT_EQ(h.matcher->decision().reason, "guided matching");
  EXPECT_TRUE(h.brute_force.destroyed);
  EXPECT_EQ(h.log.size(), 1u);  // the decision is reported once
}

// The CPU factory: auto wraps both CPU backends; an explicit type is that
// backend alone. Real matches: a pair gets the same matches as the backend
// that answered it would give alone.
TEST(AutoFeatureMatcher, CpuFactoryWrapsOnlyAuto) {
  std::mt19937 rng(9);
  std::vector<FeatureDescriptors> images(6);
  std::vector<std::vector<uint8_t>> base;
  for (int k = 0; k < 300; ++k) base.push_back(testing_support::RandomSift(&rng));
  for (FeatureDescriptors& d : images) {
    for (const auto& row : base) {
      std::vector<uint8_t> noisy = row;
      noisy[rng() % 128] ^= 1;
      d.data.insert(d.data.end(), noisy.begin(), noisy.end());
    }
  }
  std::vector<const FeatureDescriptors*> pointers;
  for (const FeatureDescriptors& d : images) pointers.push_back(&d);
  const MeanDescriptor mean = ComputeMeanDescriptor(pointers);
  const std::vector<ImagePair> pairs = AllPairs(0, 6);
  // The name as made, before any pair could decide the backend.
  auto run = [&](MatcherType type, std::string* name) {
    CasHashOptions options;
    options.matcher = type;
    auto matcher = CreateCpuFeatureMatcher(SiftMatchingOptions(), options, mean);
    *name = matcher->Name();
    for (int i = 0; i < 6; ++i) matcher->AddImage(image_t(i), images[i]);
    return matcher->MatchPairs(pairs);
  };
  std::string cascade_name, brute_name, auto_name;
  const auto cascade = run(MatcherType::kCascade, &cascade_name);
  const auto brute = run(MatcherType::kBruteForce, &brute_name);
  const auto automatic = run(MatcherType::kAuto, &auto_name);
  EXPECT_EQ(cascade_name, "cpu-cascade");
  EXPECT_EQ(brute_name, "cpu-bruteforce");
  EXPECT_EQ(auto_name, "auto(cpu-cascade|cpu-bruteforce)");
  ASSERT_EQ(automatic.size(), pairs.size());
  for (size_t p = 0; p < pairs.size(); ++p) {
    EXPECT_TRUE(automatic[p] == cascade[p] || automatic[p] == brute[p]) << p;
  }
}

}  // namespace
}  // namespace cashash

namespace cashash {
namespace {

// Runs give first_timed_call = 2: the first chunk (one block against
// itself, mostly overlapping images) is shared untimed, whatever it shows,
// and the decision comes from the next chunk.
TEST(AutoFeatureMatcher, FirstChunkIsNotTimedWhenRunsSaySo) {
  AutoMatcherOptions options;
  options.first_timed_call = 2;
  Harness h(0.004, 0.002, options);  // on the first chunk brute force looks 2x faster
  FeatureDescriptors none;
  for (int i = 0; i < 60; ++i) h.matcher->AddImage(image_t(i), none);
  const std::vector<ImagePair> pairs = AllPairs(0, 60);
  const std::vector<ImagePair> first(pairs.begin(), pairs.begin() + 400), rest(pairs.begin() + 400, pairs.end());
  h.matcher->MatchPairs(first);
  EXPECT_FALSE(h.matcher->decision().decided);
  EXPECT_EQ(h.cascade.matched.size() + h.brute_force.matched.size(), 400u);
  // A run whose later (far) pairs make the cascade 4x faster per pair.
  Harness far(0.001, 0.004, options);
  for (int i = 0; i < 60; ++i) far.matcher->AddImage(image_t(i), none);
  far.matcher->MatchPairs(first);
  EXPECT_FALSE(far.matcher->decision().decided);
  far.matcher->MatchPairs(rest);
  ASSERT_TRUE(far.matcher->decision().decided);
  EXPECT_TRUE(far.matcher->decision().cascade_won);
  EXPECT_EQ(far.cascade.matched.size() + far.brute_force.matched.size(), pairs.size());
}

}  // namespace
}  // namespace cashash
