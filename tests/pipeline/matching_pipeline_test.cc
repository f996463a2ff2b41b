#include "cashash/pipeline/matching_pipeline.h"

#include <atomic>
#include <map>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>

#include <gtest/gtest.h>

#include "cashash/base/pair_id.h"

namespace cashash {
namespace {

class FakeSource : public FeatureSource {
 public:
  explicit FakeSource(int throw_on_image = -1) : throw_on_image_(throw_on_image) { camera_.params = {100, 50, 50}; }
  ImageFeatures LoadFeatures(image_t image_id) override {
    if (static_cast<int>(image_id) == throw_on_image_) throw std::runtime_error("image 3 is broken");
    ++loads[image_id];
    ImageFeatures f;
    f.image_id = image_id;
    f.keypoints.resize(image_id);  // image i has i features
    f.descriptors.data.assign(image_id * kDescriptorDim, static_cast<uint8_t>(image_id));
    return f;
  }
  const Camera& CameraOfImage(image_t) const override { return camera_; }
  std::map<image_t, int> loads;

 private:
  Camera camera_;
  int throw_on_image_;
};

// Returns min(n1, n2) matches (k, k) and checks the images were added.
class FakeMatcher : public MatchingBackend {
 public:
  FakeMatcher() : MatchingBackend(MatcherTraits{"fake"}) {}
  void AddImage(const Image& image) override { sizes_[image.id] = image.descriptors->rows(); }
  using FeatureMatcher::AddImage;
  void RemoveImage(image_t id) override { sizes_.erase(id); }
  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override { return Match(pairs); }
  std::unique_ptr<ExactMatcher> HoldForExact(const std::vector<ImagePair>&) override { return nullptr; }
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& = {}) override {
    std::vector<FeatureMatches> out;
    for (const ImagePair& p : pairs) {
      if (!sizes_.count(p.first) || !sizes_.count(p.second)) throw std::logic_error("image not added");
      FeatureMatches m;
      for (point2D_t k = 0; k < std::min(sizes_[p.first], sizes_[p.second]); ++k) m.push_back({k, k});
      out.push_back(m);
    }
    return out;
  }
  size_t num_added() const { return sizes_.size(); }

 private:
  std::map<image_t, size_t> sizes_;
};

class CollectingSink : public ResultSink {
 public:
  void WriteChunk(const std::vector<PairResult>& results) override {
    std::lock_guard<std::mutex> lock(mutex);
    for (const PairResult& r : results) {
      EXPECT_TRUE(written.emplace(ImagePairToPairId(r.pair.first, r.pair.second), r.matches.size()).second)
          << "pair written twice";
    }
    ++chunks;
  }
  std::mutex mutex;
  std::map<pair_t, size_t> written;
  int chunks = 0;
};

std::vector<image_t> Ids(image_t n) {
  std::vector<image_t> ids;
  for (image_t i = 1; i <= n; ++i) ids.push_back(i);
  return ids;
}

PipelineOptions NoVerification() {
  PipelineOptions options;
  options.skip_geometric_verification = true;
  options.num_threads = 2;
  return options;
}

TEST(MatchingPipeline, EveryPairMatchedAndWrittenOnce) {
  FakeSource source;
  FakeMatcher matcher;
  CollectingSink sink;
  MatchingPipeline pipeline(NoVerification(), &source, &matcher, &sink);
  size_t progress_calls = 0;
  pipeline.SetProgressCallback([&](const PipelineProgress& p) {
    ++progress_calls;
    EXPECT_LE(p.pairs_done, p.pairs_total);
  });
  const PipelineStats stats = pipeline.Run(ExhaustivePairChunks(Ids(13), 4));
  EXPECT_EQ(stats.pairs_total, 78u);
  EXPECT_EQ(stats.pairs_done, 78u);
  EXPECT_EQ(sink.written.size(), 78u);
  EXPECT_EQ(sink.written.at(ImagePairToPairId(3, 9)), 3u);
  EXPECT_EQ(progress_calls, static_cast<size_t>(sink.chunks));
  EXPECT_FALSE(stats.stopped);
  // Blocks stay loaded while needed: the first block is loaded once.
  EXPECT_EQ(source.loads.at(1), 1);
  // Images not needed by the last chunks were released from the matcher.
  EXPECT_LE(matcher.num_added(), 8u);
}

// Records each chunk's pairs in the order they are written.
class OrderSink : public ResultSink {
 public:
  void WriteChunk(const std::vector<PairResult>& results) override {
    std::vector<ImagePair> pairs;
    for (const PairResult& r : results) pairs.push_back(r.pair);
    chunks.push_back(std::move(pairs));
  }
  std::vector<std::vector<ImagePair>> chunks;
};

TEST(MatchingPipeline, ChunksMadeOnDemandAreWrittenAsTheListWouldBe) {
  const std::vector<image_t> ids = Ids(23);
  const std::vector<PairChunk> listed = ScheduledPairChunks(ids, 3, 2);
  const ScheduledChunkSource made(ids, 3, 2);
  std::vector<std::vector<ImagePair>> written[2];
  std::vector<std::pair<int, int>> blocks[2];
  for (int run = 0; run < 2; ++run) {
    FakeSource source;
    FakeMatcher matcher;
    OrderSink sink;
    MatchingPipeline pipeline(NoVerification(), &source, &matcher, &sink);
    // The chunk a progress call names is alive while it is reported.
    pipeline.SetProgressCallback(
        [&](const PipelineProgress& p) { blocks[run].emplace_back(p.chunk->block_i, p.chunk->block_j); });
    const PipelineStats stats = run == 0 ? pipeline.Run(listed) : pipeline.Run(made);
    EXPECT_EQ(stats.pairs_total, 23u * 22u / 2u);
    EXPECT_EQ(stats.pairs_done, 23u * 22u / 2u);
    written[run] = sink.chunks;
  }
  EXPECT_EQ(written[0].size(), listed.size());
  EXPECT_EQ(written[0], written[1]);
  EXPECT_EQ(blocks[0], blocks[1]);
}

// The cascade of FakeMatcher, and as exact matches of pair (a, b) a matches
// (image a's rows). Records the threads the exact matches were
// made on; the exact call numbered `fail_at` throws.
class RematchedMatcher : public FakeMatcher {
 public:
  explicit RematchedMatcher(int fail_at = -1) : fail_at_(fail_at) {}
  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override {
    Match(pairs);  // checks the images are still held
    return Exact(pairs);
  }
  std::unique_ptr<ExactMatcher> HoldForExact(const std::vector<ImagePair>& pairs) override {
    Match(pairs);  // checks the images are held now
    matching_thread = std::this_thread::get_id();
    return std::make_unique<Held>(this);
  }
  std::atomic<int> completed{0};
  std::thread::id matching_thread;
  std::mutex mutex;
  std::set<std::thread::id> exact_threads;

 private:
  class Held : public ExactMatcher {
   public:
    explicit Held(RematchedMatcher* owner) : owner_(owner) {}
    std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override { return owner_->Exact(pairs); }

   private:
    RematchedMatcher* owner_;
  };
  std::vector<FeatureMatches> Exact(const std::vector<ImagePair>& pairs) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      exact_threads.insert(std::this_thread::get_id());
    }
    if (calls_++ == fail_at_) throw std::runtime_error("rematch failed on purpose");
    std::vector<FeatureMatches> out(pairs.size());
    for (size_t k = 0; k < pairs.size(); ++k) {
      const image_t a = pairs[k].first;
      for (point2D_t m = 0; m < a; ++m) out[k].push_back({m, m});
    }
    ++completed;
    return out;
  }
  const int fail_at_;
  std::atomic<int> calls_{0};
};

// Every pair with a cascade match (all of them: image i has i >= 1 rows).
ExactRematchPolicy EveryPair(RematchPlace where) {
  ExactRematchPolicy policy;
  policy.min_matches = 1;
  policy.where = where;
  return policy;
}

// On the verification threads, the rematch is complete before verification
// and writing; skipped verification writes chunks at once.
TEST(MatchingPipeline, TheRematchOnTheVerificationThreadsIsCompleteBeforeVerifyingAndWriting) {
  for (const bool skip_verification : {true, false}) {
    SCOPED_TRACE(testing::Message() << "skip " << skip_verification);
    FakeSource source;
    RematchedMatcher matcher;
    ExactRematchStage rematch(EveryPair(RematchPlace::kVerificationThread), &matcher);
    CollectingSink sink;
    PipelineOptions options = NoVerification();
    options.skip_geometric_verification = skip_verification;
    MatchingPipeline pipeline(options, &source, &matcher, &sink);
    pipeline.SetExactRematch(&rematch);
    const std::vector<PairChunk> chunks = ExhaustivePairChunks(Ids(9), 3);
    const PipelineStats stats = pipeline.Run(chunks);
    EXPECT_EQ(stats.pairs_done, 36u);
    EXPECT_EQ(matcher.completed.load(), static_cast<int>(chunks.size()));
    EXPECT_EQ(rematch.counts().rematched.load(), 36u);
    EXPECT_EQ(matcher.exact_threads.count(matcher.matching_thread), 0u) << "not on the matching thread";
    ASSERT_EQ(sink.written.size(), 36u);
    // Pair (a, b) got a matches: the exact ones.
    for (const auto& [pair_id, n] : sink.written) EXPECT_EQ(n, PairIdToImagePair(pair_id).first);
  }
}

// On the matching thread the rematch happens right after the cascade, from
// the images the backend holds then.
TEST(MatchingPipeline, TheRematchOnTheMatchingThreadRunsThere) {
  FakeSource source;
  RematchedMatcher matcher;
  ExactRematchStage rematch(EveryPair(RematchPlace::kMatchingThread), &matcher);
  CollectingSink sink;
  MatchingPipeline pipeline(NoVerification(), &source, &matcher, &sink);
  pipeline.SetExactRematch(&rematch);
  const std::vector<PairChunk> chunks = ExhaustivePairChunks(Ids(9), 3);
  pipeline.Run(chunks);
  EXPECT_EQ(matcher.exact_threads, (std::set<std::thread::id>{std::this_thread::get_id()}));
  ASSERT_EQ(sink.written.size(), 36u);
  for (const auto& [pair_id, n] : sink.written) EXPECT_EQ(n, PairIdToImagePair(pair_id).first);
}

// A failure of the rematch on a verification thread stops the run with
// that error; only whole chunks were written, in order.
TEST(MatchingPipeline, ARematchErrorStopsTheRun) {
  FakeSource source;
  RematchedMatcher matcher(/*fail_at=*/3);
  ExactRematchStage rematch(EveryPair(RematchPlace::kVerificationThread), &matcher);
  CollectingSink sink;
  PipelineOptions options = NoVerification();
  options.skip_geometric_verification = false;
  MatchingPipeline pipeline(options, &source, &matcher, &sink);
  pipeline.SetExactRematch(&rematch);
  const std::vector<PairChunk> chunks = ExhaustivePairChunks(Ids(15), 3);
  try {
    pipeline.Run(chunks);
    FAIL() << "the error was not rethrown";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "rematch failed on purpose");
  }
  EXPECT_LE(sink.chunks, 3);
  size_t pairs = 0;
  for (int c = 0; c < sink.chunks; ++c) pairs += chunks[c].pairs.size();
  EXPECT_EQ(sink.written.size(), pairs);
  for (int c = 0; c < sink.chunks; ++c) {
    for (const ImagePair& p : chunks[c].pairs) EXPECT_TRUE(sink.written.count(ImagePairToPairId(p.first, p.second)));
  }
}

// Keypoints travel with an image only to a matcher whose traits say it reads
// them (guided matching), shared with the loaded features.
class KeypointCheckingMatcher : public FeatureMatcher {
 public:
  explicit KeypointCheckingMatcher(bool uses_keypoints)
      : FeatureMatcher(MatcherTraits{"keypoints", false, uses_keypoints}) {}
  void AddImage(const Image& image) override {
    if (image.keypoints) {
      ++with_keypoints;
      EXPECT_EQ(image.keypoints->size(), image.descriptors->rows()) << "the image's own keypoints";
    }
    inner_.AddImage(image);
  }
  void RemoveImage(image_t id) override { inner_.RemoveImage(id); }
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& guides = {}) override {
    return inner_.Match(pairs, guides);
  }
  int with_keypoints = 0;

 private:
  FakeMatcher inner_;
};

TEST(MatchingPipeline, KeypointsGoOnlyToAMatcherThatReadsThem) {
  for (const bool uses_keypoints : {false, true}) {
    FakeSource source;
    KeypointCheckingMatcher matcher(uses_keypoints);
    CollectingSink sink;
    MatchingPipeline pipeline(NoVerification(), &source, &matcher, &sink);
    pipeline.Run(ExhaustivePairChunks(Ids(6), 3));
    EXPECT_EQ(matcher.with_keypoints > 0, uses_keypoints);
    EXPECT_EQ(sink.written.size(), 15u);
  }
}

TEST(MatchingPipeline, StopFlagEndsAfterCommittedChunks) {
  FakeSource source;
  FakeMatcher matcher;
  CollectingSink sink;
  MatchingPipeline pipeline(NoVerification(), &source, &matcher, &sink);
  std::atomic<bool> stop{false};
  pipeline.SetStopFlag(&stop);
  pipeline.SetProgressCallback([&](const PipelineProgress&) { stop = true; });
  const PipelineStats stats = pipeline.Run(ExhaustivePairChunks(Ids(20), 3));
  EXPECT_TRUE(stats.stopped);
  EXPECT_LT(stats.pairs_done, stats.pairs_total);
  EXPECT_EQ(sink.written.size(), stats.pairs_done);  // whatever is counted was written
}

TEST(MatchingPipeline, SourceErrorPropagatesAndNothingHalfWritten) {
  FakeSource source(/*throw_on_image=*/3);
  FakeMatcher matcher;
  CollectingSink sink;
  MatchingPipeline pipeline(NoVerification(), &source, &matcher, &sink);
  EXPECT_THROW(pipeline.Run(ExhaustivePairChunks(Ids(6), 2)), std::runtime_error);
  // Only whole chunks reached the sink: chunk (block 0, block 0) = pair (1,2).
  for (const auto& [pair_id, n] : sink.written) {
    const ImagePair p = PairIdToImagePair(pair_id);
    EXPECT_NE(p.first, 3u);
    EXPECT_NE(p.second, 3u);
  }
}

TEST(MatchingPipeline, TooFewMatchesAreDegenerate) {
  FakeSource source;
  FakeMatcher matcher;
  CollectingSink sink;
  PipelineOptions options;
  options.num_threads = 2;
  MatchingPipeline pipeline(options, &source, &matcher, &sink);
  const PipelineStats stats = pipeline.Run(ExhaustivePairChunks(Ids(5), 50));
  EXPECT_EQ(stats.pairs_done, 10u);
  EXPECT_EQ(stats.verified_pairs, 0u);  // at most 4 matches per pair < min_num_inliers
}

}  // namespace
}  // namespace cashash
