// The pipeline's verification stage hands whole chunks to the batch verifier
// it is given (the GPU one in production) and stores what it returns.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "cashash/pipeline/batch_verifier.h"
#include "cashash/pipeline/matching_pipeline.h"
#include "cashash/pipeline/pair_generation.h"
#include "cashash/pipeline/pipeline_trace.h"

namespace cashash {
namespace {

class PointSource : public FeatureSource {
 public:
  ImageFeatures LoadFeatures(image_t image_id) override {
    ImageFeatures f;
    f.image_id = image_id;
    f.keypoints.resize(30);
    for (size_t i = 0; i < f.keypoints.size(); ++i) {
      f.keypoints[i].x = static_cast<float>(i * image_id);
      f.keypoints[i].y = static_cast<float>(i + image_id);
    }
    f.descriptors.data.assign(f.keypoints.size() * kDescriptorDim, 0);
    return f;
  }
  const Camera& CameraOfImage(image_t) const override { return camera_; }

 private:
  Camera camera_;
};

// 20 matches (k, k) per pair.
class IdentityMatcher : public FeatureMatcher {
 public:
  IdentityMatcher() : FeatureMatcher(MatcherTraits{"identity"}) {}
  void AddImage(const Image&) override {}
  void RemoveImage(image_t) override {}
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& = {}) override {
    std::vector<FeatureMatches> out(pairs.size());
    for (FeatureMatches& m : out)
      for (point2D_t k = 0; k < 20; ++k) m.push_back({k, k});
    return out;
  }
};

// An IdentityMatcher that counts its Match calls.
class CountingMatcher : public IdentityMatcher {
 public:
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& = {}) override {
    ++calls;
    return IdentityMatcher::Match(pairs);
  }
  std::atomic<int> calls{0};
};

// Marks every pair UNCALIBRATED with its first match as the only inlier and
// records the batch sizes and what it was shown.
class RecordingVerifier : public BatchVerifier {
 public:
  explicit RecordingVerifier(size_t chunks_per_call = 1) : chunks_per_call_(chunks_per_call) {}
  std::string Name() const override { return "recording"; }
  size_t ChunksPerCall() const override { return chunks_per_call_; }
  std::vector<TwoViewGeometry> Verify(const std::vector<VerificationPair>& pairs) override {
    batch_sizes.push_back(pairs.size());
    std::vector<TwoViewGeometry> out(pairs.size());
    for (size_t k = 0; k < pairs.size(); ++k) {
      EXPECT_EQ(pairs[k].matches->size(), 20u);
      EXPECT_EQ(pairs[k].points1->size(), 30u);
      seeds.push_back(pairs[k].random_seed);
      out[k].config = kUncalibrated;
      out[k].inlier_matches.push_back(pairs[k].matches->front());
    }
    return out;
  }
  std::vector<size_t> batch_sizes;
  std::vector<uint64_t> seeds;

 private:
  size_t chunks_per_call_;
};

// Verifies up to three chunks at once. Every third call is slow, so calls
// finish out of order; call `fail_at` (if any) throws.
class ConcurrentVerifier : public BatchVerifier {
 public:
  explicit ConcurrentVerifier(int fail_at = -1, size_t chunks_per_call = 1)
      : fail_at_(fail_at), chunks_per_call_(chunks_per_call) {}
  std::string Name() const override { return "concurrent"; }
  int MaxConcurrentCalls() const override { return 3; }
  size_t ChunksPerCall() const override { return chunks_per_call_; }
  std::vector<TwoViewGeometry> Verify(const std::vector<VerificationPair>& pairs) override {
    const int now = ++in_flight_;
    int seen = max_in_flight.load();
    while (now > seen && !max_in_flight.compare_exchange_weak(seen, now)) {
    }
    const int call = calls_++;
    std::this_thread::sleep_for(std::chrono::milliseconds(call % 3 == 0 ? 60 : 5));
    --in_flight_;
    if (call == fail_at_) throw std::runtime_error("verifier failed on purpose");
    std::vector<TwoViewGeometry> out(pairs.size());
    for (size_t k = 0; k < pairs.size(); ++k) {
      out[k].config = kUncalibrated;
      out[k].inlier_matches.push_back(pairs[k].matches->front());
    }
    return out;
  }
  std::atomic<int> max_in_flight{0};

 private:
  const int fail_at_;
  const size_t chunks_per_call_;
  std::atomic<int> calls_{0};
  std::atomic<int> in_flight_{0};
};

class Sink : public ResultSink {
 public:
  void WriteChunk(const std::vector<PairResult>& results) override {
    std::lock_guard<std::mutex> lock(mutex);
    for (const PairResult& r : results) configs[r.pair] = r.geometry.config;
    if (!results.empty()) first_pairs.push_back(results.front().pair);
  }
  std::mutex mutex;
  std::map<ImagePair, int> configs;
  std::vector<ImagePair> first_pairs;  // of each chunk, in the order written
};

// Exhaustive chunks of images 1..num_images in blocks of `block`.
std::vector<PairChunk> Chunks(image_t num_images, size_t block) {
  std::vector<image_t> ids;
  for (image_t i = 1; i <= num_images; ++i) ids.push_back(i);
  return ExhaustivePairChunks(ids, block);
}

size_t NumPairs(const std::vector<PairChunk>& chunks) {
  size_t num_pairs = 0;
  for (const PairChunk& c : chunks) num_pairs += c.pairs.size();
  return num_pairs;
}

std::vector<ImagePair> FirstPairs(const std::vector<PairChunk>& chunks) {
  std::vector<ImagePair> first;
  for (const PairChunk& c : chunks) first.push_back(c.pairs.front());
  return first;
}

// Runs `chunks` through a pipeline of two threads from a PointSource, with
// `matcher`, `verifier` and `sink`; what Run throws passes through.
PipelineStats RunPipeline(const std::vector<PairChunk>& chunks, FeatureMatcher* matcher, BatchVerifier* verifier,
                          Sink* sink, PipelineOptions options = PipelineOptions()) {
  PointSource source;
  options.num_threads = 2;
  MatchingPipeline pipeline(options, &source, matcher, sink);
  pipeline.SetBatchVerifier(verifier);
  return pipeline.Run(chunks);
}

TEST(BatchVerifierPipeline, WholeChunksGoToTheGivenVerifier) {
  const std::vector<PairChunk> chunks = Chunks(9, 4);
  const size_t num_pairs = NumPairs(chunks);
  PointSource source;
  IdentityMatcher matcher;
  Sink sink;
  RecordingVerifier verifier;
  PipelineOptions options;
  options.num_threads = 2;
  options.two_view.random_seed = 5;
  MatchingPipeline pipeline(options, &source, &matcher, &sink);
  pipeline.SetBatchVerifier(&verifier);
  const PipelineStats stats = pipeline.Run(chunks);
  EXPECT_EQ(stats.pairs_done, num_pairs);
  EXPECT_EQ(stats.verified_pairs, num_pairs);
  EXPECT_EQ(stats.inlier_matches, num_pairs);
  ASSERT_EQ(verifier.batch_sizes.size(), chunks.size());
  for (size_t c = 0; c < chunks.size(); ++c) EXPECT_EQ(verifier.batch_sizes[c], chunks[c].pairs.size());
  ASSERT_EQ(sink.configs.size(), num_pairs);
  for (const auto& entry : sink.configs) EXPECT_EQ(entry.second, kUncalibrated);
  // Each pair is seeded from the run's seed and the pair alone.
  size_t i = 0;
  for (const PairChunk& c : chunks)
    for (const ImagePair& p : c.pairs) EXPECT_EQ(verifier.seeds[i++], PairRandomSeed(5, p));
}

TEST(BatchVerifierPipeline, SkippingVerificationNeverCallsTheVerifier) {
  PointSource source;
  IdentityMatcher matcher;
  Sink sink;
  RecordingVerifier verifier;
  PipelineOptions options;
  options.skip_geometric_verification = true;
  MatchingPipeline pipeline(options, &source, &matcher, &sink);
  pipeline.SetBatchVerifier(&verifier);
  pipeline.Run(ExhaustivePairChunks({1, 2, 3}, 2));
  EXPECT_TRUE(verifier.batch_sizes.empty());
  for (const auto& entry : sink.configs) EXPECT_EQ(entry.second, kUndefined);
}

TEST(BatchVerifierPipeline, ChunksVerifiedAtOnceAreWrittenInMatchingOrder) {
  const std::vector<PairChunk> chunks = Chunks(16, 3);
  ASSERT_GE(chunks.size(), 10u);
  const size_t num_pairs = NumPairs(chunks);
  IdentityMatcher matcher;
  Sink sink;
  ConcurrentVerifier verifier;
  const PipelineStats stats = RunPipeline(chunks, &matcher, &verifier, &sink);
  EXPECT_EQ(stats.verification_threads, 3);
  EXPECT_EQ(stats.pairs_done, num_pairs);
  EXPECT_EQ(stats.verified_pairs, num_pairs);
  // The slow calls let the next chunks overtake them; they still wait.
  EXPECT_GE(verifier.max_in_flight.load(), 2);
  EXPECT_LE(verifier.max_in_flight.load(), 3);
  EXPECT_EQ(sink.first_pairs, FirstPairs(chunks));
  ASSERT_EQ(sink.configs.size(), num_pairs);
  for (const auto& entry : sink.configs) EXPECT_EQ(entry.second, kUncalibrated);
}

TEST(BatchVerifierPipeline, FailedConcurrentChunkStopsTheRunAndWritesNoLaterChunk) {
  // One chunk per call, and calls of up to three chunks that wait together.
  for (const size_t chunks_per_call : {size_t{1}, size_t{3}}) {
    const std::vector<PairChunk> chunks = Chunks(16, 3);
    IdentityMatcher matcher;
    Sink sink;
    ConcurrentVerifier verifier(/*fail_at=*/4, chunks_per_call);
    PipelineOptions options;
    try {
      RunPipeline(chunks, &matcher, &verifier, &sink, options);
      FAIL() << "the verifier's error was not rethrown";
    } catch (const std::runtime_error& e) {
      EXPECT_STREQ(e.what(), "verifier failed on purpose");
    }
    // Whole chunks only, in matching order, and none after the failed one.
    const std::vector<ImagePair> all = FirstPairs(chunks);
    ASSERT_LT(sink.first_pairs.size(), all.size()) << chunks_per_call;
    EXPECT_TRUE(std::equal(sink.first_pairs.begin(), sink.first_pairs.end(), all.begin())) << chunks_per_call;
    size_t written_pairs = 0;
    for (size_t c = 0; c < sink.first_pairs.size(); ++c) written_pairs += chunks[c].pairs.size();
    EXPECT_EQ(sink.configs.size(), written_pairs) << chunks_per_call;
  }
}

// Chunks differ in cost, so matching may run ahead of a slow verification
// by the queue's depth, and no further: the first chunk's verification is
// held until matching has stopped, then released.
TEST(BatchVerifierPipeline, MatchingRunsAheadOfASlowChunkByTheQueueDepth) {
  const std::vector<PairChunk> chunks = Chunks(40, 4);  // 55 chunks
  for (const size_t depth : {size_t{2}, size_t{6}}) {
    CountingMatcher matcher;
    Sink sink;
    class HeldVerifier : public RecordingVerifier {
     public:
      HeldVerifier(CountingMatcher* m, int expected) : m_(m), expected_(expected) {}
      std::vector<TwoViewGeometry> Verify(const std::vector<VerificationPair>& pairs) override {
        if (first_) {
          first_ = false;
          // Matching fills the queue, then blocks: wait for the full
          // queue, then long enough to see it go no further.
          const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(20);
          while (m_->calls.load() < expected_ && std::chrono::steady_clock::now() < give_up) {
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
          }
          std::this_thread::sleep_for(std::chrono::milliseconds(200));
          calls_while_held = m_->calls.load();
        }
        return RecordingVerifier::Verify(pairs);
      }
      int calls_while_held = 0;

     private:
      CountingMatcher* m_;
      const int expected_;
      bool first_ = true;
    } verifier(&matcher, static_cast<int>(depth) + 2);
    PipelineOptions options;
    options.chunks_in_queue = depth;
    const PipelineStats stats = RunPipeline(chunks, &matcher, &verifier, &sink, options);
    EXPECT_EQ(stats.pairs_done, NumPairs(chunks));
    // The chunk held, `depth` queued, and one matched that waits to be queued.
    EXPECT_EQ(verifier.calls_while_held, static_cast<int>(depth) + 2) << "depth " << depth;
    EXPECT_EQ(sink.first_pairs, FirstPairs(chunks));
  }
}

// A verifier of two chunks at once (as the GPU one) that records how many
// of its calls ran at the same time.
class TwoAtOnceVerifier : public RecordingVerifier {
 public:
  int MaxConcurrentCalls() const override { return 2; }
  std::vector<TwoViewGeometry> Verify(const std::vector<VerificationPair>& pairs) override {
    const int now = ++in_flight;
    int seen = max_in_flight.load();
    while (now > seen && !max_in_flight.compare_exchange_weak(seen, now)) {
    }
    std::vector<TwoViewGeometry> out;
    {
      std::lock_guard<std::mutex> lock(mutex_);  // RecordingVerifier's vectors
      out = RecordingVerifier::Verify(pairs);
    }
    Hold();
    --in_flight;
    ++verified;
    return out;
  }
  virtual void Hold() { std::this_thread::sleep_for(std::chrono::milliseconds(2)); }
  std::atomic<int> in_flight{0}, max_in_flight{0}, verified{0};

 private:
  std::mutex mutex_;
};

// While matching keeps ahead of one verification thread, the second takes
// nothing: matching shares the device with one chunk's RANSAC, not two.
// The matcher here matches a chunk only once the previous one is verified,
// so the queue never fills.
TEST(BatchVerifierPipeline, ASecondVerifierWaitsWhileMatchingKeepsUp) {
  const std::vector<PairChunk> chunks = Chunks(12, 3);  // 10 chunks
  TwoAtOnceVerifier verifier;
  class PacedMatcher : public IdentityMatcher {
   public:
    explicit PacedMatcher(TwoAtOnceVerifier* v) : v_(v) {}
    std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& = {}) override {
      const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(20);
      while (v_->verified.load() < calls_ && std::chrono::steady_clock::now() < give_up) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
      ++calls_;
      return IdentityMatcher::Match(pairs);
    }

   private:
    TwoAtOnceVerifier* v_;
    int calls_ = 0;
  } matcher(&verifier);
  Sink sink;
  const PipelineStats stats = RunPipeline(chunks, &matcher, &verifier, &sink);
  EXPECT_EQ(stats.verification_threads, 2);
  EXPECT_EQ(stats.pairs_done, NumPairs(chunks));
  EXPECT_EQ(verifier.max_in_flight.load(), 1);
  EXPECT_EQ(sink.first_pairs, FirstPairs(chunks));
}

// Once the queue to verification is full (matching is about to wait), the
// second thread verifies too: the first thread's chunk is held here until
// another call starts, which only the second thread can make.
TEST(BatchVerifierPipeline, ASecondVerifierStartsOnceTheQueueIsFull) {
  const std::vector<PairChunk> chunks = Chunks(24, 3);  // 36 chunks
  CountingMatcher matcher;
  class HeldFirstVerifier : public TwoAtOnceVerifier {
   public:
    explicit HeldFirstVerifier(CountingMatcher* m) : m_(m) {}
    void Hold() override {
      if (!held_.exchange(true)) {
        holding_ = true;
        const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(20);
        while (!second_while_held.load() && std::chrono::steady_clock::now() < give_up) {
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
        holding_ = false;
      } else if (holding_.load() && !second_while_held.load()) {
        matched_when_second = m_->calls.load();
        second_while_held = true;
      }
    }
    std::atomic<bool> second_while_held{false};
    std::atomic<int> matched_when_second{0};

   private:
    CountingMatcher* m_;
    std::atomic<bool> held_{false}, holding_{false};
  } verifier(&matcher);
  Sink sink;
  PipelineOptions options;
  options.chunks_in_queue = 3;
  const PipelineStats stats = RunPipeline(chunks, &matcher, &verifier, &sink, options);
  EXPECT_TRUE(verifier.second_while_held.load());
  // Long before matching ended (36 chunks): the held chunk, the second
  // thread's, the queue of 3 full again, one matched chunk waiting.
  EXPECT_LE(verifier.matched_when_second.load(), 6);
  EXPECT_EQ(stats.pairs_done, NumPairs(chunks));
  EXPECT_EQ(sink.first_pairs, FirstPairs(chunks));
}

// Chunks that wait together go to the verifier in one call: in matching
// order, each pair once, each geometry back to its own pair. The extra
// chunks of a call keep their room in the queue, so matching runs no
// further ahead than with one chunk per call.
TEST(BatchVerifierPipeline, ChunksThatWaitTogetherShareOneCall) {
  const std::vector<PairChunk> chunks = Chunks(40, 4);  // 55 chunks
  const size_t depth = 6;
  CountingMatcher matcher;
  Sink sink;
  // The first call is held until matching has filled the queue, the second
  // long enough to see how far matching then goes. A pair's configuration
  // follows its seed, so a geometry handed to the wrong pair shows.
  class HeldCallsVerifier : public BatchVerifier {
   public:
    explicit HeldCallsVerifier(CountingMatcher* m) : m_(m) {}
    std::string Name() const override { return "held"; }
    size_t ChunksPerCall() const override { return 4; }
    std::vector<TwoViewGeometry> Verify(const std::vector<VerificationPair>& pairs) override {
      const size_t call = batch_sizes.size();
      batch_sizes.push_back(pairs.size());
      if (call == 0) {
        const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(20);
        while (m_->calls.load() < static_cast<int>(depth) + 2 && std::chrono::steady_clock::now() < give_up) {
          std::this_thread::sleep_for(std::chrono::milliseconds(5));
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
      } else if (call == 1) {
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
        calls_during_second = m_->calls.load();
      }
      std::vector<TwoViewGeometry> out(pairs.size());
      for (size_t k = 0; k < pairs.size(); ++k) {
        out[k].config = pairs[k].random_seed % 2 ? kUncalibrated : kCalibrated;
        out[k].inlier_matches.push_back(pairs[k].matches->front());
      }
      return out;
    }
    std::vector<size_t> batch_sizes;
    int calls_during_second = 0;

   private:
    CountingMatcher* m_;
  } verifier(&matcher);
  PipelineOptions options;
  options.chunks_in_queue = depth;
  options.two_view.random_seed = 3;
  const PipelineStats stats = RunPipeline(chunks, &matcher, &verifier, &sink, options);
  EXPECT_EQ(stats.pairs_done, NumPairs(chunks));
  EXPECT_EQ(stats.verified_pairs, NumPairs(chunks));
  EXPECT_EQ(stats.verification_calls, verifier.batch_sizes.size());
  // Each call's pairs are those of consecutive chunks, at most four.
  std::vector<size_t> chunks_per_call;
  size_t c = 0;
  for (const size_t pairs : verifier.batch_sizes) {
    size_t sum = 0, taken = 0;
    while (sum < pairs && c < chunks.size()) {
      sum += chunks[c++].pairs.size();
      ++taken;
    }
    ASSERT_EQ(sum, pairs) << "a call that is not whole chunks";
    EXPECT_LE(taken, 4u);
    chunks_per_call.push_back(taken);
  }
  EXPECT_EQ(c, chunks.size());
  ASSERT_GE(chunks_per_call.size(), 2u);
  // When the first call ends at least three chunks wait: the second takes them.
  EXPECT_GE(chunks_per_call[1], 3u);
  // While a call is held matching fills the queue and stops: the chunks
  // taken before, `depth` queued or held by the call, one matched and
  // waiting. Had the call's extra chunks given their room back, matching
  // would have gone chunks_per_call[1] - 1 further.
  EXPECT_EQ(verifier.calls_during_second, static_cast<int>(chunks_per_call[0] + depth + 2));
  EXPECT_EQ(sink.first_pairs, FirstPairs(chunks));
  ASSERT_EQ(sink.configs.size(), NumPairs(chunks));
  for (const auto& entry : sink.configs) {
    EXPECT_EQ(entry.second, PairRandomSeed(3, entry.first) % 2 ? kUncalibrated : kCalibrated);
  }
}

// A traced run records each chunk's stages once, in the order a chunk goes
// through them, and a verifier call's chunks share its interval.
TEST(BatchVerifierPipeline, TheTraceHasEachChunksStagesInOrder) {
  const std::vector<PairChunk> chunks = Chunks(12, 3);  // 10 chunks
  IdentityMatcher matcher;
  Sink sink;
  RecordingVerifier verifier(/*chunks_per_call=*/2);
  PipelineTrace trace;
  PipelineOptions options;
  options.trace = &trace;
  const PipelineStats stats = RunPipeline(chunks, &matcher, &verifier, &sink, options);
  ASSERT_EQ(stats.pairs_done, NumPairs(chunks));
  std::map<std::pair<size_t, std::string>, PipelineTraceEvent> by_chunk;
  std::map<size_t, std::pair<double, double>> calls;
  const std::vector<PipelineTraceEvent> events = trace.Events();
  for (const PipelineTraceEvent& e : events) {
    EXPECT_LE(e.start, e.end) << e.stage;
    EXPECT_TRUE(by_chunk.emplace(std::make_pair(e.chunk, e.stage), e).second) << e.stage << " twice";
    EXPECT_NE(e.stage, "rematch") << "nothing was deferred";
    if (e.stage == "verify") {
      EXPECT_GE(e.call, 1u);
      const auto [it, added] = calls.emplace(e.call, std::make_pair(e.start, e.end));
      if (!added) {
        EXPECT_EQ(it->second, std::make_pair(e.start, e.end)) << "call " << e.call;
      }
    }
  }
  EXPECT_EQ(calls.size(), stats.verification_calls);
  EXPECT_EQ(events.size(), 4 * chunks.size());
  for (size_t c = 0; c < chunks.size(); ++c) {
    const PipelineTraceEvent& load = by_chunk.at({c, "load"});
    const PipelineTraceEvent& match = by_chunk.at({c, "match"});
    const PipelineTraceEvent& verify = by_chunk.at({c, "verify"});
    const PipelineTraceEvent& write = by_chunk.at({c, "write"});
    EXPECT_LE(load.end, match.start);
    EXPECT_LE(match.end, verify.start);
    EXPECT_LE(verify.end, write.start);
    EXPECT_EQ(match.thread, 0);
    EXPECT_GE(verify.thread, 1);
    EXPECT_EQ(write.thread, -1);
    EXPECT_EQ(write.pairs, chunks[c].pairs.size());
  }
}

TEST(PipelineTrace, WritesOneLinePerEventAndNamesAPathItCannotWrite) {
  PipelineTrace trace;
  trace.Record({"write", 1, 0, -1, 0.5, 0.75, 6});
  trace.Record({"match", 0, 0, 0, 0.25, 0.5, 6});
  ASSERT_EQ(trace.Events().front().stage, "match");  // by start time
  const std::string path = ::testing::TempDir() + "pipeline_trace_test.csv";
  EXPECT_EQ(trace.WriteCsv(path), 2u);
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_EQ(lines[0], "stage,chunk,call,thread,start,end,pairs");
  EXPECT_EQ(lines[1], "match,0,0,0,0.250000,0.500000,6");
  EXPECT_EQ(lines[2], "write,1,0,-1,0.500000,0.750000,6");
  std::remove(path.c_str());
  try {
    trace.WriteCsv("/nonexistent-folder/trace.csv");
    FAIL() << "no error for a path that cannot be written";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent-folder/trace.csv"), std::string::npos);
  }
}

}  // namespace
}  // namespace cashash
