// GroupFeatureCache under the real pipeline: features are read from the
// source as often as the schedule predicts, host memory never holds more
// than three groups, every pair is still matched once with the right data.
#include "cashash/pipeline/feature_cache.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <tuple>
#include <map>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>

#include <gtest/gtest.h>

#include "cashash/pipeline/pair_generation.h"
#include "cashash/base/pair_id.h"

namespace cashash {
namespace {

constexpr size_t kFeaturesPerImage = 10;
constexpr size_t kImageBytes = kFeaturesPerImage * (kDescriptorDim + sizeof(Keypoint));

// Image i has kFeaturesPerImage features whose bytes are (i mod 256); counts
// loads. With concurrent_loads 1 it checks that no two threads read at once;
// with more it allows that and records the most reads seen at once.
class CountingSource : public FeatureSource {
 public:
  explicit CountingSource(int broken_image = -1, int delay_us = 0, int concurrent_loads = 1)
      : broken_image_(broken_image), delay_us_(delay_us), concurrent_loads_(concurrent_loads) {
    camera_.params = {100, 50, 50};
  }
  ImageFeatures LoadFeatures(image_t image_id) override {
    std::unique_lock<std::mutex> busy(busy_, std::defer_lock);
    if (concurrent_loads_ == 1) busy.try_lock();
    const int now = ++reading_;
    for (int seen = most_at_once.load(); now > seen && !most_at_once.compare_exchange_weak(seen, now);) {
    }
    // A slow disk: the pipeline then waits for the loader instead of the
    // loader waiting for the pipeline; reads must not change.
    if (delay_us_ > 0) std::this_thread::sleep_for(std::chrono::microseconds(delay_us_));
    --reading_;
    if (concurrent_loads_ == 1) {
      EXPECT_TRUE(busy.owns_lock()) << "source read from two threads at once";
    }
    if (static_cast<int>(image_id) == broken_image_) throw std::runtime_error("image is broken");
    {
      std::lock_guard<std::mutex> lock(loads_mutex_);
      ++loads[image_id];
    }
    ImageFeatures f;
    f.image_id = image_id;
    f.keypoints.resize(kFeaturesPerImage);
    f.descriptors.data.assign(kFeaturesPerImage * kDescriptorDim, static_cast<uint8_t>(image_id));
    return f;
  }
  const Camera& CameraOfImage(image_t) const override { return camera_; }
  int MaxConcurrentLoads() const override { return concurrent_loads_; }
  std::map<image_t, int> loads;
  std::atomic<int> most_at_once{0};

 private:
  std::mutex busy_;
  std::mutex loads_mutex_;
  std::atomic<int> reading_{0};
  Camera camera_;
  int broken_image_;
  int delay_us_;
  int concurrent_loads_;
};

// Matches (k, k) for every feature, after checking each image's bytes are
// its own (the cache must hand out the right image).
class CheckingMatcher : public FeatureMatcher {
 public:
  CheckingMatcher() : FeatureMatcher(MatcherTraits{"checking"}) {}
  void AddImage(const Image& image) override {
    const image_t id = image.id;
    const FeatureDescriptors& d = *image.descriptors;
    for (uint8_t byte : d.data) {
      if (byte != static_cast<uint8_t>(id)) throw std::logic_error("wrong features for image " + std::to_string(id));
    }
    sizes_[id] = d.rows();
  }
  void RemoveImage(image_t id) override { sizes_.erase(id); }
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& = {}) override {
    std::vector<FeatureMatches> out;
    for (const ImagePair& p : pairs) {
      if (!sizes_.count(p.first) || !sizes_.count(p.second)) throw std::logic_error("image not added");
      FeatureMatches m;
      for (point2D_t k = 0; k < sizes_[p.first]; ++k) m.push_back({k, k});
      out.push_back(m);
    }
    return out;
  }

 private:
  std::map<image_t, size_t> sizes_;
};

class CollectingSink : public ResultSink {
 public:
  void WriteChunk(const std::vector<PairResult>& results) override {
    for (const PairResult& r : results) {
      EXPECT_TRUE(pairs.insert(ImagePairToPairId(r.pair.first, r.pair.second)).second) << "pair written twice";
      EXPECT_EQ(r.matches.size(), kFeaturesPerImage);
    }
  }
  std::set<pair_t> pairs;
};

std::vector<image_t> Ids(size_t n) {
  std::vector<image_t> ids;
  for (size_t i = 1; i <= n; ++i) ids.push_back(static_cast<image_t>(i));
  return ids;
}

FeatureCacheStats RunPipeline(CountingSource* source, const std::vector<PairChunk>& chunks, CollectingSink* sink) {
  GroupFeatureCache cache(source, chunks);
  CheckingMatcher matcher;
  PipelineOptions options;
  options.skip_geometric_verification = true;
  options.num_threads = 2;
  MatchingPipeline pipeline(options, &cache, &matcher, sink);
  pipeline.Run(chunks);
  return cache.stats();
}

struct Layout {
  size_t n;
  int block_size;
  int blocks_per_group;
};

// (source delay in microseconds, the source's MaxConcurrentLoads)
class GroupFeatureCacheLoads : public ::testing::TestWithParam<std::tuple<int, int>> {};

TEST_P(GroupFeatureCacheLoads, AsPredictedAndAtMostThreeGroupsHeld) {
  for (const Layout& l : {Layout{24, 3, 2}, Layout{25, 3, 2}, Layout{30, 4, 3}, Layout{7, 2, 1}, Layout{12, 5, 10},
                          Layout{40, 2, 3}}) {
    SCOPED_TRACE("n=" + std::to_string(l.n) + " block_size=" + std::to_string(l.block_size) +
                 " blocks_per_group=" + std::to_string(l.blocks_per_group));
    const std::vector<PairChunk> chunks = ScheduledPairChunks(Ids(l.n), l.block_size, l.blocks_per_group);
    const auto [delay_us, concurrent_loads] = GetParam();
    CountingSource source(-1, delay_us, concurrent_loads);
    CollectingSink sink;
    const FeatureCacheStats stats = RunPipeline(&source, chunks, &sink);
    EXPECT_EQ(sink.pairs.size(), l.n * (l.n - 1) / 2);
    EXPECT_LE(source.most_at_once.load(), concurrent_loads);
    // Slow reads of a step of 4 or more images overlap when allowed to.
    if (concurrent_loads > 1 && delay_us > 0 && l.n >= 8) {
      EXPECT_GT(source.most_at_once.load(), 1);
    }

    // Predicted from the group pairs alone: a group pair (a step) needs its
    // groups; what the previous step and this one need stays in memory,
    // anything else is forgotten and read again when needed (row i of the
    // group-pair table reads G0 and the groups after Gi, less what the
    // previous row left behind).
    const size_t group_images = static_cast<size_t>(l.block_size * l.blocks_per_group);
    const size_t groups = (l.n + group_images - 1) / group_images;
    auto images_of_group = [&](int g) { return std::min(group_images, l.n - g * group_images); };
    std::vector<std::set<int>> steps;
    for (const PairChunk& chunk : chunks) {
      const std::set<int> need = {chunk.group_i, chunk.group_j};
      const bool held = !steps.empty() && std::includes(steps.back().begin(), steps.back().end(), need.begin(),
                                                        need.end());
      if (!held) steps.push_back(need);
    }
    size_t predicted = 0;
    std::set<int> held;
    for (size_t s = 0; s < steps.size(); ++s) {
      std::set<int> keep = steps[s];
      if (s > 0) keep.insert(steps[s - 1].begin(), steps[s - 1].end());
      std::set<int> next;
      for (int g : held) {
        if (keep.count(g)) next.insert(g);
      }
      for (int g : steps[s]) {
        if (!next.count(g)) predicted += images_of_group(g);
        next.insert(g);
      }
      held = next;
    }
    // Never more than one group load per group pair.
    EXPECT_LE(predicted, (1 + groups * (groups - 1) / 2) * group_images);
    size_t loads = 0;
    for (const auto& entry : source.loads) loads += entry.second;
    EXPECT_EQ(loads, predicted);
    EXPECT_EQ(stats.source_loads, predicted);
    EXPECT_EQ(stats.unplanned, 0u);
    EXPECT_EQ(stats.steps, groups == 1 ? 1 : groups * (groups - 1) / 2 + 1);
    // The cap: the current group pair and the next one's new group.
    EXPECT_LE(stats.peak_bytes, 3 * std::min(group_images, l.n) * kImageBytes);
    EXPECT_GT(stats.peak_bytes, 0u);
  }
}

// Source reads taking no time (the loader runs ahead) and 300 us (the
// pipeline waits for it), by one loading thread and by four: the same loads.
INSTANTIATE_TEST_SUITE_P(SourceDelayAndConcurrentLoads, GroupFeatureCacheLoads,
                         ::testing::Combine(::testing::Values(0, 300), ::testing::Values(1, 4)));

TEST(GroupFeatureCache, ResumedScheduleStillMatchesEveryPairOnce) {
  std::vector<PairChunk> chunks = ScheduledPairChunks(Ids(30), 3, 2);
  // Pairs whose ids sum to a multiple of 3 are "already in the database".
  chunks = RemovePairs(std::move(chunks), [](const ImagePair& p) { return (p.first + p.second) % 3 == 0; });
  size_t expected = 0;
  for (const PairChunk& chunk : chunks) expected += chunk.pairs.size();
  CountingSource source;
  CollectingSink sink;
  const FeatureCacheStats stats = RunPipeline(&source, chunks, &sink);
  EXPECT_EQ(sink.pairs.size(), expected);
  EXPECT_EQ(stats.unplanned, 0u);
}

TEST(GroupFeatureCache, RequestsOutsideThePlanGoToTheSource) {
  const std::vector<PairChunk> chunks = ScheduledPairChunks(Ids(12), 2, 2);
  CountingSource source;
  GroupFeatureCache cache(&source, chunks);
  EXPECT_EQ(cache.LoadFeatures(99).descriptors.data[0], 99);  // in no chunk
  EXPECT_EQ(cache.LoadFeatures(1).descriptors.data[0], 1);
  EXPECT_EQ(cache.stats().unplanned, 1u);
}

TEST(GroupFeatureCache, LoadErrorReachesThePipeline) {
  const std::vector<PairChunk> chunks = ScheduledPairChunks(Ids(12), 2, 2);
  CountingSource source(/*broken_image=*/7);
  CollectingSink sink;
  EXPECT_THROW(RunPipeline(&source, chunks, &sink), std::runtime_error);
}

TEST(GroupFeatureCache, StepsFollowGroupPairs) {
  // 8 images, blocks of 2, groups of 2 blocks: steps G0xG0, G0xG1 (+ G1xG1,
  // whose images are all held already).
  const std::vector<std::vector<image_t>> steps = GroupFeatureCache::Steps(ScheduledPairChunks(Ids(8), 2, 2));
  ASSERT_EQ(steps.size(), 2u);
  EXPECT_EQ(std::set<image_t>(steps[0].begin(), steps[0].end()), (std::set<image_t>{1, 2, 3, 4}));
  EXPECT_EQ(std::set<image_t>(steps[1].begin(), steps[1].end()), (std::set<image_t>{1, 2, 3, 4, 5, 6, 7, 8}));
}

}  // namespace
}  // namespace cashash
