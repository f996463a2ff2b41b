// The exact rematch stage: the cascade screens, exact matching decides.
// Pairs with at least min_matches cascade matches (and fewer than
// max_matches where set) get the backend's exact matches, the others keep
// the cascade's, in the callers' order; on the matching thread at once, on
// a verification thread from held images, with the pool's matchers where
// held images find no device memory. On the CPU the exact matches are brute
// force's, match for match.
#include "cashash/pipeline/exact_rematch_stage.h"

#include <random>
#include <set>
#include <stdexcept>
#include <thread>

#include <gtest/gtest.h>

#include "cashash/base/device_memory_error.h"
#include "synthetic_sift.h"
#include "cascade_options.h"

namespace cashash {
namespace {

using testing_support::CascadeOptions;

// Answers pair (a, b) with a + b cascade matches whose idx2 is 1, or
// exactly with a + b + 1 matches whose idx2 is 2, and records what it is
// asked. Its held images answer exactly too, or throw DeviceMemoryError.
class CannedMatcher : public MatchingBackend {
 public:
  CannedMatcher() : MatchingBackend(MatcherTraits{"canned"}) {}
  void AddImage(const Image& image) override { images.insert(image.id); }
  using FeatureMatcher::AddImage;
  void RemoveImage(image_t id) override { images.erase(id); }
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& = {}) override {
    asked.insert(asked.end(), pairs.begin(), pairs.end());
    return Answer(pairs, 0, 1);
  }
  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override {
    asked_exact.insert(asked_exact.end(), pairs.begin(), pairs.end());
    return Answer(pairs, 1, 2);
  }
  std::unique_ptr<ExactMatcher> HoldForExact(const std::vector<ImagePair>& pairs) override {
    for (const ImagePair& p : pairs) {
      EXPECT_TRUE(images.count(p.first) && images.count(p.second)) << "held while the images are added";
    }
    held_pairs.insert(held_pairs.end(), pairs.begin(), pairs.end());
    return std::make_unique<Held>(this);
  }

  static std::vector<FeatureMatches> Answer(const std::vector<ImagePair>& pairs, size_t extra, point2D_t tag) {
    std::vector<FeatureMatches> out;
    for (const ImagePair& p : pairs) {
      FeatureMatches m;
      for (size_t k = 0; k < p.first + p.second + extra; ++k) m.push_back({static_cast<point2D_t>(k), tag});
      out.push_back(std::move(m));
    }
    return out;
  }

  std::set<image_t> images;
  std::vector<ImagePair> asked, asked_exact, held_pairs;
  int alive = 0;               // held matchers not yet let go
  int held_runs = 0;           // MatchExact calls of held matchers
  bool out_of_memory = false;  // held matchers throw DeviceMemoryError

 private:
  class Held : public ExactMatcher {
   public:
    explicit Held(CannedMatcher* owner) : owner_(owner) { ++owner_->alive; }
    ~Held() override { --owner_->alive; }
    std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override {
      ++owner_->held_runs;
      if (owner_->out_of_memory) throw DeviceMemoryError("GPU memory budget exceeded by brute-force scratch");
      return Answer(pairs, 1, 2);
    }

   private:
    CannedMatcher* owner_;
  };
};

ExactRematchPolicy Policy(size_t min_matches, RematchPlace where, size_t max_matches = 0) {
  ExactRematchPolicy policy;
  policy.min_matches = min_matches;
  policy.max_matches = max_matches;
  policy.where = where;
  return policy;
}

const std::vector<ImagePair> kPairs = {{0, 1}, {1, 4}, {0, 2}, {2, 3}, {0, 4}, {1, 2}};

TEST(ExactRematchStage, PairsThatMayVerifyGetTheExactMatches) {
  CannedMatcher backend;
  for (image_t id = 0; id < 5; ++id) backend.AddImage(id, FeatureDescriptors{});
  ExactRematchStage stage(Policy(5, RematchPlace::kMatchingThread), &backend);
  std::vector<FeatureMatches> results = backend.Match(kPairs);
  const PendingRematch pending = stage.AfterMatching(kPairs, &results);
  EXPECT_TRUE(pending.empty()) << "nothing is left for later on the matching thread";
  ASSERT_EQ(results.size(), kPairs.size());
  // Cascade counts: 1, 5, 2, 5, 4, 3 -> (1,4) and (2,3) are matched again.
  EXPECT_EQ(backend.asked_exact, (std::vector<ImagePair>{{1, 4}, {2, 3}}));
  for (size_t i = 0; i < kPairs.size(); ++i) {
    const size_t cascade_count = kPairs[i].first + kPairs[i].second;
    const bool again = cascade_count >= 5;
    ASSERT_EQ(results[i].size(), again ? cascade_count + 1 : cascade_count) << i;
    for (const FeatureMatch& m : results[i]) EXPECT_EQ(m.point2D_idx2, again ? 2u : 1u) << i;
  }
  EXPECT_EQ(stage.counts().pairs.load(), 6u);
  EXPECT_EQ(stage.counts().rematched.load(), 2u);
}

// A window [min, max): only the pairs near the verification threshold are
// matched again; those above it keep the cascade's matches.
TEST(ExactRematchStage, AWindowRematchesOnlyThePairsInsideIt) {
  CannedMatcher backend;
  for (image_t id = 0; id < 5; ++id) backend.AddImage(id, FeatureDescriptors{});
  ExactRematchStage stage(Policy(3, RematchPlace::kMatchingThread, 5), &backend);
  std::vector<FeatureMatches> results = backend.Match(kPairs);
  stage.AfterMatching(kPairs, &results);
  // Cascade counts: 1, 5, 2, 5, 4, 3 -> (0,4) and (1,2) lie in [3, 5).
  EXPECT_EQ(backend.asked_exact, (std::vector<ImagePair>{{0, 4}, {1, 2}}));
  for (size_t i = 0; i < kPairs.size(); ++i) {
    const size_t cascade_count = kPairs[i].first + kPairs[i].second;
    const bool again = cascade_count >= 3 && cascade_count < 5;
    ASSERT_EQ(results[i].size(), again ? cascade_count + 1 : cascade_count) << i;
  }
  EXPECT_EQ(stage.counts().rematched.load(), 2u);
}

// The policy is the one place that says which pairs are matched again.
TEST(ExactRematchStage, ThePolicySelectsAndChecks) {
  EXPECT_FALSE(ExactRematchPolicy().enabled());
  EXPECT_FALSE(ExactRematchPolicy().Selects(100));
  const ExactRematchPolicy at_least = Policy(12, RematchPlace::kVerificationThread);
  EXPECT_FALSE(at_least.Selects(11));
  EXPECT_TRUE(at_least.Selects(12));
  EXPECT_TRUE(at_least.Selects(100000));
  const ExactRematchPolicy window = Policy(12, RematchPlace::kMatchingThread, 64);
  EXPECT_TRUE(window.Selects(63));
  EXPECT_FALSE(window.Selects(64));
  EXPECT_EQ(ExactRematchPolicy().Check(), "");
  EXPECT_EQ(window.Check(), "");
  EXPECT_NE(Policy(0, RematchPlace::kMatchingThread).Check(), "");
  EXPECT_NE(Policy(5, RematchPlace::kMatchingThread, 5).Check(), "");
  EXPECT_STREQ(RematchPlaceName(RematchPlace::kVerificationThread), "verification thread");
}

TEST(ExactRematchStage, NowhereKeepsTheCascadesMatches) {
  CannedMatcher backend;
  for (image_t id = 0; id < 5; ++id) backend.AddImage(id, FeatureDescriptors{});
  ExactRematchStage stage(ExactRematchPolicy(), nullptr);
  std::vector<FeatureMatches> results = backend.Match(kPairs);
  const std::vector<FeatureMatches> cascade = results;
  EXPECT_TRUE(stage.AfterMatching(kPairs, &results).empty());
  EXPECT_EQ(results, cascade);
  EXPECT_EQ(stage.counts().pairs.load(), 0u);
}

TEST(ExactRematchStage, RejectsAnInvalidPolicyOrNoBackend) {
  CannedMatcher backend;
  EXPECT_THROW(ExactRematchStage(Policy(5, RematchPlace::kMatchingThread), nullptr), std::invalid_argument);
  EXPECT_THROW(ExactRematchStage(Policy(0, RematchPlace::kMatchingThread), &backend), std::invalid_argument);
  EXPECT_THROW(ExactRematchStage(Policy(5, RematchPlace::kMatchingThread, 5), &backend), std::invalid_argument);
}

// With the CPU cascade the rematched pairs' matches are brute force's, match
// for match, and the others the cascade's.
TEST(ExactRematchStage, RematchedPairsEqualBruteForceOnTheCpu) {
  std::mt19937 rng(11);
  std::vector<std::vector<uint8_t>> base;
  for (int k = 0; k < 300; ++k) base.push_back(testing_support::RandomSift(&rng));
  std::uniform_int_distribution<int> noise(-6, 6);
  std::vector<FeatureDescriptors> images(4);
  for (int i = 0; i < 4; ++i) {
    // Images 0-2 share the base descriptors (with noise); image 3 is unrelated.
    for (int k = 0; k < 300; ++k) {
      const std::vector<uint8_t> b = i < 3 ? base[k] : testing_support::RandomSift(&rng);
      for (uint8_t x : b) images[i].data.push_back(static_cast<uint8_t>(std::clamp(int(x) + noise(rng), 0, 255)));
    }
  }
  std::vector<const FeatureDescriptors*> pointers;
  for (const FeatureDescriptors& d : images) pointers.push_back(&d);
  const MeanDescriptor mean = ComputeMeanDescriptor(pointers);
  SiftMatchingOptions sift;
  sift.num_threads = 1;
  CasHashOptions cascade_options = CascadeOptions(), brute_options = CascadeOptions();
  brute_options.matcher = MatcherType::kBruteForce;
  auto cascade = CreateCpuFeatureMatcher(sift, cascade_options, mean);
  auto brute_ref = CreateCpuFeatureMatcher(sift, brute_options, mean);
  for (image_t id = 0; id < 4; ++id) {
    cascade->AddImage(id, images[id]);
    brute_ref->AddImage(id, images[id]);
  }
  ExactRematchStage stage(Policy(15, RematchPlace::kMatchingThread), cascade.get());
  const std::vector<ImagePair> pairs = {{0, 1}, {0, 3}, {1, 2}, {2, 3}};
  const auto cascade_results = cascade->Match(pairs);
  auto results = cascade_results;
  stage.AfterMatching(pairs, &results);
  const auto brute_results = brute_ref->Match(pairs);
  size_t rematched = 0;
  for (size_t i = 0; i < pairs.size(); ++i) {
    const bool again = cascade_results[i].size() >= 15;
    rematched += again;
    const FeatureMatches& expected = again ? brute_results[i] : cascade_results[i];
    ASSERT_EQ(results[i].size(), expected.size()) << i;
    for (size_t k = 0; k < expected.size(); ++k) {
      EXPECT_EQ(results[i][k].point2D_idx1, expected[k].point2D_idx1);
      EXPECT_EQ(results[i][k].point2D_idx2, expected[k].point2D_idx2);
    }
  }
  // Pairs of overlapping images are matched again, those of the unrelated
  // image are not.
  EXPECT_GE(rematched, 2u);
  EXPECT_LT(cascade_results[1].size(), 15u);
  EXPECT_EQ(stage.counts().rematched.load(), rematched);
}

// On a verification thread: the cascade's matches come back at once, the
// pairs that reach the threshold are held (what the backend held when the
// chunk was matched, even once the images are gone from it) and completed
// later, never by the pool nor from the caller's descriptors; the held
// images are let go once used, or when the chunk is dropped.
TEST(ExactRematchStage, OnAVerificationThreadTheHeldImagesAreMatchedLater) {
  CannedMatcher backend;
  auto pool = std::make_shared<ExactMatcherPool>([]() { return std::make_unique<CannedMatcher>(); });
  ExactRematchStage stage(Policy(5, RematchPlace::kVerificationThread), &backend, pool);
  for (image_t id = 0; id < 5; ++id) backend.AddImage(id, FeatureDescriptors{});
  std::vector<FeatureMatches> matches = backend.Match(kPairs);
  PendingRematch pending = stage.AfterMatching(kPairs, &matches);
  ASSERT_FALSE(pending.empty());
  for (const FeatureMatches& m : matches) {
    for (const FeatureMatch& match : m) EXPECT_EQ(match.point2D_idx2, 1u) << "the cascade's matches at first";
  }
  EXPECT_EQ(backend.held_pairs, (std::vector<ImagePair>{{1, 4}, {2, 3}}));
  EXPECT_TRUE(backend.asked_exact.empty());
  EXPECT_EQ(backend.alive, 1);
  EXPECT_EQ(stage.counts().rematched.load(), 0u);
  for (image_t id = 0; id < 5; ++id) backend.RemoveImage(id);  // the matcher goes on
  bool looked_up = false;
  std::thread([&] {
    stage.Complete(
        &pending,
        [&](image_t) {
          looked_up = true;
          return std::make_shared<const FeatureDescriptors>();
        },
        &matches);
  }).join();
  EXPECT_FALSE(looked_up) << "the held images need no descriptors from the caller";
  EXPECT_EQ(pool->made(), 0u);
  EXPECT_EQ(backend.alive, 0) << "let go once used";
  EXPECT_TRUE(pending.empty());
  // (1,4) and (2,3): the exact answer (a + b + 1 matches tagged 2).
  ASSERT_EQ(matches[1].size(), 6u);
  ASSERT_EQ(matches[3].size(), 6u);
  EXPECT_EQ(matches[1][0].point2D_idx2, 2u);
  EXPECT_EQ(matches[0][0].point2D_idx2, 1u) << "below the threshold: the cascade's";
  EXPECT_EQ(stage.counts().rematched.load(), 2u);
  // A chunk dropped before it is completed (a failed run) lets go too.
  for (image_t id = 0; id < 5; ++id) backend.AddImage(id, FeatureDescriptors{});
  {
    std::vector<FeatureMatches> dropped = backend.Match({{2, 3}});
    const PendingRematch left = stage.AfterMatching({{2, 3}}, &dropped);
    EXPECT_EQ(backend.alive, 1);
  }
  EXPECT_EQ(backend.alive, 0);
  // Nothing reaches the threshold: nothing is held.
  std::vector<FeatureMatches> few = backend.Match({{0, 1}});
  EXPECT_TRUE(stage.AfterMatching({{0, 1}}, &few).empty());
}

// Held images that find no room on the device do not end the run: their
// pairs go to the pool's matchers (which themselves go on on the CPU when
// the device has no room for them either), fed with the caller's
// descriptors, and the run's counts say so; the pool's matcher is reused.
TEST(ExactRematchStage, HeldImagesOutOfDeviceMemoryGoToThePool) {
  CannedMatcher backend;
  backend.out_of_memory = true;
  std::vector<CannedMatcher*> made;
  auto pool = std::make_shared<ExactMatcherPool>([&made]() {
    auto exact = std::make_unique<CannedMatcher>();
    made.push_back(exact.get());
    return exact;
  });
  ExactRematchStage stage(Policy(5, RematchPlace::kVerificationThread), &backend, pool);
  for (image_t id = 0; id < 5; ++id) backend.AddImage(id, FeatureDescriptors{});
  std::vector<FeatureMatches> matches = backend.Match(kPairs);
  PendingRematch pending = stage.AfterMatching(kPairs, &matches);
  std::set<image_t> looked_up;
  auto descriptors = std::make_shared<const FeatureDescriptors>();
  const auto lookup = [&](image_t id) {
    looked_up.insert(id);
    return descriptors;
  };
  EXPECT_NO_THROW(stage.Complete(&pending, lookup, &matches));
  EXPECT_EQ(backend.held_runs, 1);
  EXPECT_EQ(backend.alive, 0) << "the failed held images are let go";
  ASSERT_EQ(made.size(), 1u);
  // The pooled matcher answers with Match (tag 1, a + b matches).
  EXPECT_EQ(made[0]->asked, (std::vector<ImagePair>{{1, 4}, {2, 3}}));
  EXPECT_TRUE(made[0]->images.empty()) << "images removed before the matcher goes back to the pool";
  EXPECT_EQ(looked_up, (std::set<image_t>{1, 2, 3, 4}));
  EXPECT_EQ(matches[1].size(), 5u) << "the pool's answer";
  EXPECT_EQ(stage.counts().held_without_memory.load(), 1u);
  EXPECT_EQ(stage.counts().rematched.load(), 2u);
  // The matcher went back to the pool: a second chunk reuses it.
  std::vector<FeatureMatches> again = backend.Match({{2, 3}});
  PendingRematch second = stage.AfterMatching({{2, 3}}, &again);
  stage.Complete(&second, lookup, &again);
  EXPECT_EQ(pool->made(), 1u);
  EXPECT_EQ(stage.counts().held_without_memory.load(), 2u);
  // Without a pool the error reaches the caller.
  ExactRematchStage without_pool(Policy(5, RematchPlace::kVerificationThread), &backend);
  std::vector<FeatureMatches> third = backend.Match({{2, 3}});
  PendingRematch failing = without_pool.AfterMatching({{2, 3}}, &third);
  EXPECT_THROW(without_pool.Complete(&failing, lookup, &third), DeviceMemoryError);
}

// On the CPU backend, rematches held on the matching thread and completed on
// other threads while the cascade goes on give what the rematch at once
// gives.
TEST(ExactRematchStage, HeldOnOtherThreadsEqualsTheRematchAtOnce) {
  std::mt19937 rng(5);
  std::vector<std::vector<uint8_t>> base;
  for (int k = 0; k < 200; ++k) base.push_back(testing_support::RandomSift(&rng));
  std::uniform_int_distribution<int> noise(-6, 6);
  std::vector<std::shared_ptr<FeatureDescriptors>> images;
  for (int i = 0; i < 6; ++i) {
    auto d = std::make_shared<FeatureDescriptors>();
    for (int k = 0; k < 200; ++k) {
      const std::vector<uint8_t> b = i % 3 != 2 ? base[k] : testing_support::RandomSift(&rng);
      for (uint8_t x : b) d->data.push_back(static_cast<uint8_t>(std::clamp(int(x) + noise(rng), 0, 255)));
    }
    images.push_back(d);
  }
  std::vector<const FeatureDescriptors*> pointers;
  for (const auto& d : images) pointers.push_back(d.get());
  const MeanDescriptor mean = ComputeMeanDescriptor(pointers);
  SiftMatchingOptions sift;
  sift.num_threads = 1;
  const CasHashOptions cascade_options = CascadeOptions();
  auto deferred_backend = CreateCpuFeatureMatcher(sift, cascade_options, mean);
  auto at_once_backend = CreateCpuFeatureMatcher(sift, cascade_options, mean);
  ExactRematchStage deferred(Policy(15, RematchPlace::kVerificationThread), deferred_backend.get());
  ExactRematchStage at_once(Policy(15, RematchPlace::kMatchingThread), at_once_backend.get());
  for (image_t id = 0; id < 6; ++id) {
    deferred_backend->AddImage(MatcherImage{id, nullptr, images[id]});
    at_once_backend->AddImage(MatcherImage{id, nullptr, images[id]});
  }
  const std::vector<std::vector<ImagePair>> chunks = {{{0, 1}, {0, 2}, {0, 3}}, {{1, 3}, {1, 4}, {2, 5}},
                                                      {{3, 4}, {0, 4}, {1, 5}}, {{4, 5}, {2, 3}, {0, 5}}};
  std::vector<std::vector<FeatureMatches>> matched(chunks.size());
  std::vector<PendingRematch> pending(chunks.size());
  std::vector<std::thread> completing;
  for (size_t c = 0; c < chunks.size(); ++c) {
    matched[c] = deferred_backend->Match(chunks[c]);
    pending[c] = deferred.AfterMatching(chunks[c], &matched[c]);
    if (pending[c].empty()) continue;
    completing.emplace_back([&, c]() {
      deferred.Complete(&pending[c], [&](image_t id) { return images.at(id); }, &matched[c]);
    });
  }
  for (image_t id = 0; id < 6; ++id) deferred_backend->RemoveImage(id);  // the held images stay
  for (std::thread& t : completing) t.join();
  for (size_t c = 0; c < chunks.size(); ++c) {
    std::vector<FeatureMatches> expected = at_once_backend->Match(chunks[c]);
    at_once.AfterMatching(chunks[c], &expected);
    EXPECT_EQ(matched[c], expected) << c;
  }
  EXPECT_EQ(deferred.counts().rematched.load(), at_once.counts().rematched.load());
  EXPECT_GE(deferred.counts().rematched.load(), 4u) << "pairs of overlapping images are matched again";
}

}  // namespace
}  // namespace cashash
