// The pipeline's verification stage hands whole chunks to the batch verifier
// it is given (the GPU one in production) and stores what it returns.
#include <gtest/gtest.h>

#include <map>
#include <mutex>

#include "cashash/batch_verifier.h"
#include "cashash/matching_pipeline.h"
#include "cashash/pair_generation.h"

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
  void AddImage(image_t, const FeatureDescriptors&) override {}
  void RemoveImage(image_t) override {}
  std::vector<FeatureMatches> MatchPairs(const std::vector<ImagePair>& pairs) override {
    std::vector<FeatureMatches> out(pairs.size());
    for (FeatureMatches& m : out)
      for (point2D_t k = 0; k < 20; ++k) m.push_back({k, k});
    return out;
  }
  std::string Name() const override { return "identity"; }
};

// Marks every pair UNCALIBRATED with its first match as the only inlier and
// records the batch sizes and what it was shown.
class RecordingVerifier : public BatchVerifier {
 public:
  std::string Name() const override { return "recording"; }
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
};

class Sink : public ResultSink {
 public:
  void WriteChunk(const std::vector<PairResult>& results) override {
    std::lock_guard<std::mutex> lock(mutex);
    for (const PairResult& r : results) configs[r.pair] = r.geometry.config;
  }
  std::mutex mutex;
  std::map<ImagePair, int> configs;
};

TEST(BatchVerifierPipeline, WholeChunksGoToTheGivenVerifier) {
  std::vector<image_t> ids;
  for (image_t i = 1; i <= 9; ++i) ids.push_back(i);
  const std::vector<PairChunk> chunks = ExhaustivePairChunks(ids, 4);
  size_t num_pairs = 0;
  for (const PairChunk& c : chunks) num_pairs += c.pairs.size();
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

}  // namespace
}  // namespace cashash
