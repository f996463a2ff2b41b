// The cascade screens, exact matching decides: pairs with at least
// min_matches cascade matches get the backend's exact matches, the others
// keep the cascade's, in the callers' order. On the CPU the exact matches
// are brute force's, match for match.
#include "cashash/matchers/exact_rematch_feature_matcher.h"

#include <random>
#include <set>
#include <stdexcept>
#include <thread>

#include <gtest/gtest.h>

#include "cashash/base/device_memory_error.h"
#include "synthetic_sift.h"

namespace cashash {
namespace {

// Answers pair (a, b) with a + b cascade matches whose idx2 is 1, or
// exactly with a + b + 1 matches whose idx2 is 2, and records what it is
// asked.
class CannedMatcher : public FeatureMatcher {
 public:
  explicit CannedMatcher(bool exact = true) : exact_(exact) {}
  void AddImage(image_t id, const FeatureDescriptors&) override { images.insert(id); }
  void RemoveImage(image_t id) override { images.erase(id); }
  std::vector<FeatureMatches> MatchPairs(const std::vector<ImagePair>& pairs) override {
    asked.insert(asked.end(), pairs.begin(), pairs.end());
    return Answer(pairs, 0, 1);
  }
  std::string Name() const override { return "canned"; }
  bool SupportsEpipolarGuidance() const override { return true; }
  std::vector<FeatureMatches> MatchPairsGuided(const std::vector<GuidedPair>& pairs, double) override {
    guided_calls += pairs.size();
    return std::vector<FeatureMatches>(pairs.size());
  }
  bool SupportsExactMatching() const override { return exact_; }
  std::vector<FeatureMatches> MatchPairsExact(const std::vector<ImagePair>& pairs) override {
    asked_exact.insert(asked_exact.end(), pairs.begin(), pairs.end());
    return Answer(pairs, 1, 2);
  }
  std::set<image_t> images;
  std::vector<ImagePair> asked, asked_exact;
  size_t guided_calls = 0;

 private:
  static std::vector<FeatureMatches> Answer(const std::vector<ImagePair>& pairs, size_t extra, point2D_t tag) {
    std::vector<FeatureMatches> out;
    for (const ImagePair& p : pairs) {
      FeatureMatches m;
      for (size_t k = 0; k < p.first + p.second + extra; ++k) m.push_back({static_cast<point2D_t>(k), tag});
      out.push_back(std::move(m));
    }
    return out;
  }
  bool exact_;
};

TEST(ExactRematchFeatureMatcher, PairsThatMayVerifyGetTheExactMatches) {
  auto cascade = std::make_unique<CannedMatcher>();
  CannedMatcher* c = cascade.get();
  ExactRematchFeatureMatcher matcher(std::move(cascade), 5);
  for (image_t id = 0; id < 6; ++id) matcher.AddImage(id, FeatureDescriptors{});
  matcher.RemoveImage(5);
  EXPECT_EQ(c->images, (std::set<image_t>{0, 1, 2, 3, 4}));

  const std::vector<ImagePair> pairs = {{0, 1}, {1, 4}, {0, 2}, {2, 3}, {0, 4}, {1, 2}};
  const std::vector<FeatureMatches> results = matcher.MatchPairs(pairs);
  ASSERT_EQ(results.size(), pairs.size());
  EXPECT_EQ(c->asked, pairs);
  // Cascade counts: 1, 5, 2, 5, 4, 3 -> (1,4) and (2,3) are matched again.
  EXPECT_EQ(c->asked_exact, (std::vector<ImagePair>{{1, 4}, {2, 3}}));
  for (size_t i = 0; i < pairs.size(); ++i) {
    const size_t cascade_count = pairs[i].first + pairs[i].second;
    const bool again = cascade_count >= 5;
    ASSERT_EQ(results[i].size(), again ? cascade_count + 1 : cascade_count) << i;
    for (const FeatureMatch& m : results[i]) EXPECT_EQ(m.point2D_idx2, again ? 2u : 1u) << i;
  }
  EXPECT_EQ(matcher.pairs_matched(), 6u);
  EXPECT_EQ(matcher.pairs_rematched(), 2u);
  EXPECT_EQ(matcher.Name(), "canned+exact-rematch");
}

// A window [min, max): only the pairs near the verification threshold are
// matched again; those above it keep the cascade's matches.
TEST(ExactRematchFeatureMatcher, AWindowRematchesOnlyThePairsInsideIt) {
  auto cascade = std::make_unique<CannedMatcher>();
  CannedMatcher* c = cascade.get();
  ExactRematchFeatureMatcher matcher(std::move(cascade), 3, nullptr, nullptr, 5);
  for (image_t id = 0; id < 5; ++id) matcher.AddImage(id, FeatureDescriptors{});
  const std::vector<ImagePair> pairs = {{0, 1}, {1, 4}, {0, 2}, {2, 3}, {0, 4}, {1, 2}};
  const std::vector<FeatureMatches> results = matcher.MatchPairs(pairs);
  // Cascade counts: 1, 5, 2, 5, 4, 3 -> (0,4) and (1,2) lie in [3, 5).
  EXPECT_EQ(c->asked_exact, (std::vector<ImagePair>{{0, 4}, {1, 2}}));
  for (size_t i = 0; i < pairs.size(); ++i) {
    const size_t cascade_count = pairs[i].first + pairs[i].second;
    const bool again = cascade_count >= 3 && cascade_count < 5;
    ASSERT_EQ(results[i].size(), again ? cascade_count + 1 : cascade_count) << i;
  }
  EXPECT_EQ(matcher.pairs_rematched(), 2u);
}

TEST(ExactRematchFeatureMatcher, GuidedMatchingStaysWithTheCascade) {
  auto cascade = std::make_unique<CannedMatcher>();
  CannedMatcher* c = cascade.get();
  ExactRematchFeatureMatcher matcher(std::move(cascade), 1);
  EXPECT_TRUE(matcher.SupportsEpipolarGuidance());
  matcher.MatchPairsGuided(std::vector<GuidedPair>(3), 4.0);
  EXPECT_EQ(c->guided_calls, 3u);
  EXPECT_TRUE(c->asked_exact.empty());
}

TEST(ExactRematchFeatureMatcher, RejectsABackendWithoutExactMatchingOrAZeroThreshold) {
  EXPECT_THROW(ExactRematchFeatureMatcher(nullptr, 5), std::invalid_argument);
  EXPECT_THROW(ExactRematchFeatureMatcher(std::make_unique<CannedMatcher>(false), 5), std::invalid_argument);
  EXPECT_THROW(ExactRematchFeatureMatcher(std::make_unique<CannedMatcher>(), 0), std::invalid_argument);
  EXPECT_THROW(ExactRematchFeatureMatcher(std::make_unique<CannedMatcher>(), 5, nullptr, nullptr, 5),
               std::invalid_argument);
}

// With the CPU cascade the rematched pairs' matches are brute force's, match
// for match, and the others the cascade's.
TEST(ExactRematchFeatureMatcher, RematchedPairsEqualBruteForceOnTheCpu) {
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
  CasHashOptions cascade_options, brute_options;
  brute_options.matcher = MatcherType::kBruteForce;
  auto cascade_ref = CreateCpuFeatureMatcher(sift, cascade_options, mean);
  auto brute_ref = CreateCpuFeatureMatcher(sift, brute_options, mean);
  ExactRematchFeatureMatcher matcher(CreateCpuFeatureMatcher(sift, cascade_options, mean), 15);
  for (image_t id = 0; id < 4; ++id) {
    matcher.AddImage(id, images[id]);
    cascade_ref->AddImage(id, images[id]);
    brute_ref->AddImage(id, images[id]);
  }
  const std::vector<ImagePair> pairs = {{0, 1}, {0, 3}, {1, 2}, {2, 3}};
  const auto results = matcher.MatchPairs(pairs);
  const auto cascade_results = cascade_ref->MatchPairs(pairs);
  const auto brute_results = brute_ref->MatchPairs(pairs);
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
  EXPECT_EQ(matcher.pairs_rematched(), rematched);
}

// Deferred (with a pool): the cascade's matches come back at once, the
// pairs that reach the threshold are left to Complete, which matches them
// on a pooled matcher from the caller's descriptors: the same results as
// the rematch at once, and no exact call on the cascade.
TEST(ExactRematchFeatureMatcher, DeferredRematchCompletesWithAPooledMatcherFromTheCallersDescriptors) {
  auto cascade = std::make_unique<CannedMatcher>();
  CannedMatcher* c = cascade.get();
  std::vector<CannedMatcher*> made;
  auto pool = std::make_shared<ExactMatcherPool>([&made]() {
    auto exact = std::make_unique<CannedMatcher>();
    made.push_back(exact.get());
    return exact;
  });
  ExactRematchFeatureMatcher matcher(std::move(cascade), 5, nullptr, pool);
  for (image_t id = 0; id < 5; ++id) matcher.AddImage(id, FeatureDescriptors{});
  const std::vector<ImagePair> pairs = {{0, 1}, {1, 4}, {0, 2}, {2, 3}, {0, 4}, {1, 2}};

  ChunkMatches chunk = matcher.MatchPairsDeferred(pairs);
  ASSERT_EQ(chunk.matches.size(), pairs.size());
  ASSERT_NE(chunk.deferred, nullptr);
  for (const FeatureMatches& m : chunk.matches) {
    for (const FeatureMatch& match : m) EXPECT_EQ(match.point2D_idx2, 1u) << "the cascade's matches at first";
  }
  EXPECT_EQ(matcher.pairs_rematched(), 0u);

  std::set<image_t> looked_up;
  auto descriptors = std::make_shared<const FeatureDescriptors>();
  chunk.deferred->Complete(
      [&](image_t id) {
        looked_up.insert(id);
        return descriptors;
      },
      &chunk.matches);
  // (1,4) and (2,3) reach 5 cascade matches; only their images were needed.
  EXPECT_EQ(looked_up, (std::set<image_t>{1, 2, 3, 4}));
  ASSERT_EQ(made.size(), 1u);
  // The pooled matcher answers with MatchPairs (tag 1, a + b matches).
  EXPECT_EQ(made[0]->asked, (std::vector<ImagePair>{{1, 4}, {2, 3}}));
  EXPECT_TRUE(made[0]->images.empty()) << "images removed before the matcher goes back to the pool";
  EXPECT_TRUE(c->asked_exact.empty());
  EXPECT_EQ(chunk.matches[1].size(), 5u);
  EXPECT_EQ(chunk.matches[3].size(), 5u);
  EXPECT_EQ(matcher.pairs_rematched(), 2u);

  // The matcher went back to the pool: a second chunk reuses it.
  ChunkMatches again = matcher.MatchPairsDeferred({{2, 3}});
  again.deferred->Complete([&](image_t) { return descriptors; }, &again.matches);
  EXPECT_EQ(made.size(), 1u);
  EXPECT_EQ(pool->made(), 1u);
  // Nothing reaches the threshold: nothing deferred. MatchPairs never defers.
  EXPECT_EQ(matcher.MatchPairsDeferred({{0, 1}}).deferred, nullptr);
  matcher.MatchPairs({{2, 3}});
  EXPECT_EQ(c->asked_exact, (std::vector<ImagePair>{{2, 3}}));
}

// A cascade that lends tickets: the deferred rematch runs the ticket (the
// exact matches from what the cascade held when the chunk was matched, even
// once the images are gone from it), never the pool nor the caller's
// descriptors; a ticket is run once and let go.
class TicketMatcher : public CannedMatcher {
 public:
  class Ticket : public ExactMatchingTicket {
   public:
    Ticket(std::vector<ImagePair> pairs, std::vector<FeatureMatches> answer, int* alive, bool out_of_memory)
        : pairs_(std::move(pairs)), answer_(std::move(answer)), alive_(alive), out_of_memory_(out_of_memory) {
      ++*alive_;
    }
    ~Ticket() override { --*alive_; }
    std::vector<FeatureMatches> Run() override {
      EXPECT_FALSE(ran_) << "a ticket is run once";
      ran_ = true;
      if (out_of_memory_) throw DeviceMemoryError("GPU memory budget exceeded by brute-force scratch");
      return answer_;
    }

   private:
    std::vector<ImagePair> pairs_;
    std::vector<FeatureMatches> answer_;
    int* alive_;
    bool out_of_memory_;
    bool ran_ = false;
  };
  std::unique_ptr<ExactMatchingTicket> DeferExactMatching(const std::vector<ImagePair>& pairs) override {
    for (const ImagePair& p : pairs) {
      EXPECT_TRUE(images.count(p.first) && images.count(p.second)) << "a ticket is taken while the images are held";
    }
    return std::make_unique<Ticket>(pairs, MatchPairsExact(pairs), &alive, out_of_memory);
  }
  int alive = 0;
  bool out_of_memory = false;  // its tickets throw DeviceMemoryError
};

// A ticket that finds no room on the device does not end the run: its
// pairs go to the pool's matchers (which themselves go on on the CPU when
// the device has no room for them either), fed with the caller's
// descriptors, and the run's counts say so.
TEST(ExactRematchFeatureMatcher, ATicketOutOfDeviceMemoryHandsItsPairsToThePool) {
  auto cascade = std::make_unique<TicketMatcher>();
  TicketMatcher* c = cascade.get();
  c->out_of_memory = true;
  std::vector<CannedMatcher*> made;
  auto pool = std::make_shared<ExactMatcherPool>([&made]() {
    auto exact = std::make_unique<CannedMatcher>();
    made.push_back(exact.get());
    return exact;
  });
  auto counts = std::make_shared<ExactRematchCounts>();
  ExactRematchFeatureMatcher matcher(std::move(cascade), 5, counts, pool);
  for (image_t id = 0; id < 5; ++id) matcher.AddImage(id, FeatureDescriptors{});
  const std::vector<ImagePair> pairs = {{0, 1}, {1, 4}, {0, 2}, {2, 3}, {0, 4}, {1, 2}};
  ChunkMatches chunk = matcher.MatchPairsDeferred(pairs);
  ASSERT_NE(chunk.deferred, nullptr);
  std::set<image_t> looked_up;
  auto descriptors = std::make_shared<const FeatureDescriptors>();
  EXPECT_NO_THROW(chunk.deferred->Complete(
      [&](image_t id) {
        looked_up.insert(id);
        return descriptors;
      },
      &chunk.matches));
  EXPECT_EQ(c->alive, 0) << "the failed ticket is let go";
  ASSERT_EQ(made.size(), 1u);
  EXPECT_EQ(made[0]->asked, (std::vector<ImagePair>{{1, 4}, {2, 3}}));
  EXPECT_EQ(looked_up, (std::set<image_t>{1, 2, 3, 4}));
  EXPECT_EQ(chunk.matches[1].size(), 5u) << "the pool's answer";
  EXPECT_EQ(counts->tickets_without_memory, 1u);
  EXPECT_EQ(matcher.pairs_rematched(), 2u);
}

TEST(ExactRematchFeatureMatcher, DeferredRematchRunsTheCascadesTicketWhereItGivesOne) {
  auto cascade = std::make_unique<TicketMatcher>();
  TicketMatcher* c = cascade.get();
  auto pool = std::make_shared<ExactMatcherPool>([]() { return std::make_unique<CannedMatcher>(); });
  ExactRematchFeatureMatcher matcher(std::move(cascade), 5, nullptr, pool);
  for (image_t id = 0; id < 5; ++id) matcher.AddImage(id, FeatureDescriptors{});
  const std::vector<ImagePair> pairs = {{0, 1}, {1, 4}, {0, 2}, {2, 3}, {0, 4}, {1, 2}};
  ChunkMatches chunk = matcher.MatchPairsDeferred(pairs);
  ASSERT_NE(chunk.deferred, nullptr);
  EXPECT_EQ(c->alive, 1);
  for (image_t id = 0; id < 5; ++id) matcher.RemoveImage(id);  // the matcher goes on
  bool looked_up = false;
  chunk.deferred->Complete(
      [&](image_t) {
        looked_up = true;
        return std::make_shared<const FeatureDescriptors>();
      },
      &chunk.matches);
  EXPECT_FALSE(looked_up) << "the ticket needs no descriptors from the caller";
  EXPECT_EQ(pool->made(), 0u);
  EXPECT_EQ(c->alive, 0) << "the ticket is let go once run";
  // (1,4) and (2,3): the exact answer (a + b + 1 matches tagged 2).
  ASSERT_EQ(chunk.matches[1].size(), 6u);
  ASSERT_EQ(chunk.matches[3].size(), 6u);
  EXPECT_EQ(chunk.matches[1][0].point2D_idx2, 2u);
  EXPECT_EQ(chunk.matches[0][0].point2D_idx2, 1u) << "below the threshold: the cascade's";
  EXPECT_EQ(matcher.pairs_rematched(), 2u);
  // A chunk dropped before it is completed (a failed run) lets go too.
  for (image_t id = 0; id < 5; ++id) matcher.AddImage(id, FeatureDescriptors{});
  {
    ChunkMatches dropped = matcher.MatchPairsDeferred({{2, 3}});
    EXPECT_EQ(c->alive, 1);
  }
  EXPECT_EQ(c->alive, 0);
}

// On the CPU backends, deferred rematches completed on two other threads
// while the cascade goes on give what the rematch at once gives.
TEST(ExactRematchFeatureMatcher, DeferredOnOtherThreadsEqualsTheRematchAtOnce) {
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
  CasHashOptions cascade_options, brute_options;
  brute_options.matcher = MatcherType::kBruteForce;
  auto pool = std::make_shared<ExactMatcherPool>(
      [&]() { return CreateCpuFeatureMatcher(sift, brute_options, mean); });
  ExactRematchFeatureMatcher deferred(CreateCpuFeatureMatcher(sift, cascade_options, mean), 15, nullptr, pool);
  ExactRematchFeatureMatcher at_once(CreateCpuFeatureMatcher(sift, cascade_options, mean), 15);
  for (image_t id = 0; id < 6; ++id) {
    deferred.AddImage(id, *images[id]);
    at_once.AddImage(id, *images[id]);
  }
  const std::vector<std::vector<ImagePair>> chunks = {{{0, 1}, {0, 2}, {0, 3}}, {{1, 3}, {1, 4}, {2, 5}},
                                                      {{3, 4}, {0, 4}, {1, 5}}, {{4, 5}, {2, 3}, {0, 5}}};
  std::vector<ChunkMatches> matched(chunks.size());
  std::vector<std::thread> completing;
  for (size_t c = 0; c < chunks.size(); ++c) {
    matched[c] = deferred.MatchPairsDeferred(chunks[c]);
    if (!matched[c].deferred) continue;
    completing.emplace_back([&, c]() {
      matched[c].deferred->Complete([&](image_t id) { return images.at(id); }, &matched[c].matches);
    });
  }
  for (std::thread& t : completing) t.join();
  size_t rematched = 0;
  for (size_t c = 0; c < chunks.size(); ++c) {
    const std::vector<FeatureMatches> expected = at_once.MatchPairs(chunks[c]);
    for (size_t i = 0; i < expected.size(); ++i) {
      ASSERT_EQ(matched[c].matches[i].size(), expected[i].size()) << c << " " << i;
      for (size_t k = 0; k < expected[i].size(); ++k) {
        EXPECT_EQ(matched[c].matches[i][k].point2D_idx1, expected[i][k].point2D_idx1);
        EXPECT_EQ(matched[c].matches[i][k].point2D_idx2, expected[i][k].point2D_idx2);
      }
    }
  }
  rematched = deferred.pairs_rematched();
  EXPECT_EQ(rematched, at_once.pairs_rematched());
  EXPECT_GE(rematched, 4u) << "pairs of overlapping images are matched again";
  EXPECT_GE(pool->made(), 1u);
}

}  // namespace
}  // namespace cashash
