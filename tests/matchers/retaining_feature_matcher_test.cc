// RetainingFeatureMatcher: with memory enough, every image reaches the
// matcher once for the whole scheduled run; with less, the budget holds
// (images in use aside), the oldest released go first, and results do not
// change.
#include "cashash/matchers/retaining_feature_matcher.h"

#include <map>
#include <set>
#include <stdexcept>

#include <gtest/gtest.h>

#include "cashash/pipeline/matching_pipeline.h"
#include "cashash/pipeline/pair_generation.h"
#include "cashash/base/pair_id.h"

namespace cashash {
namespace {

// Image i has i + 1 features; counts AddImage per image and what it holds.
class CountingMatcher : public FeatureMatcher {
 public:
  CountingMatcher() : FeatureMatcher(MatcherTraits{"counting", true}) {}
  void AddImage(const Image& image) override {
    if (held.count(image.id)) throw std::logic_error("added twice without removal");
    held[image.id] = image.descriptors->rows();
    ++adds[image.id];
    max_held = std::max(max_held, held.size());
  }
  using FeatureMatcher::AddImage;
  void RemoveImage(image_t id) override { held.erase(id); }
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& guides = {}) override {
    match_calls += 1;
    guided_calls += guides.empty() ? 0 : 1;
    std::vector<FeatureMatches> out;
    for (const ImagePair& p : pairs) {
      if (!held.count(p.first) || !held.count(p.second)) throw std::logic_error("image not added");
      FeatureMatches m;
      for (point2D_t k = 0; k < std::min(held[p.first], held[p.second]); ++k) m.push_back({k, k});
      out.push_back(m);
    }
    return out;
  }
  size_t match_calls = 0;
  size_t guided_calls = 0;
  std::map<image_t, size_t> held;
  std::map<image_t, int> adds;
  size_t max_held = 0;
};

class Source : public FeatureSource {
 public:
  ImageFeatures LoadFeatures(image_t id) override {
    ImageFeatures f;
    f.image_id = id;
    f.keypoints.resize(id + 1);
    f.descriptors.data.assign((id + 1) * kDescriptorDim, 7);
    return f;
  }
  const Camera& CameraOfImage(image_t) const override { return camera_; }

 private:
  Camera camera_;
};

class Sink : public ResultSink {
 public:
  void WriteChunk(const std::vector<PairResult>& results) override {
    for (const PairResult& r : results) {
      EXPECT_TRUE(sizes.emplace(ImagePairToPairId(r.pair.first, r.pair.second), r.matches.size()).second);
    }
  }
  std::map<pair_t, size_t> sizes;
};

struct RunOutcome {
  std::map<image_t, int> adds;
  size_t max_held = 0;
  RetainingStats stats;
  std::map<pair_t, size_t> results;
  size_t chunks = 0;
  size_t match_calls = 0;
};

constexpr size_t kImages = 60;

// Every image counts one "byte": budgets are numbers of images.
RunOutcome MatchAll(size_t budget_images) {
  std::vector<image_t> ids;
  for (image_t i = 1; i <= kImages; ++i) ids.push_back(i);
  const std::vector<PairChunk> chunks = ScheduledPairChunks(ids, 5, 2);
  auto counting = std::make_unique<CountingMatcher>();
  CountingMatcher* inner = counting.get();
  RetainingFeatureMatcher matcher(std::move(counting), budget_images, [](const FeatureDescriptors&) { return 1; });
  Source source;
  Sink sink;
  PipelineOptions options;
  options.skip_geometric_verification = true;
  MatchingPipeline pipeline(options, &source, &matcher, &sink);
  pipeline.Run(chunks);
  return {inner->adds, inner->max_held, matcher.stats(), sink.sizes, chunks.size(), inner->match_calls};
}

TEST(RetainingFeatureMatcher, AmpleBudgetHashesEveryImageOnce) {
  const RunOutcome run = MatchAll(kImages);
  EXPECT_EQ(run.match_calls, run.chunks);
  ASSERT_EQ(run.adds.size(), kImages);
  for (const auto& [id, count] : run.adds) EXPECT_EQ(count, 1) << "image " << id;
  EXPECT_EQ(run.stats.images_added, kImages);
  EXPECT_GT(run.stats.images_reused, 0u);
  EXPECT_EQ(run.stats.images_dropped, 0u);
  EXPECT_EQ(run.results.size(), kImages * (kImages - 1) / 2);
}

TEST(RetainingFeatureMatcher, SmallBudgetHoldsAndStillSavesWork) {
  const RunOutcome none = MatchAll(0);  // what the pipeline alone adds
  const RunOutcome some = MatchAll(25);
  size_t adds_none = 0, adds_some = 0;
  for (const auto& entry : none.adds) adds_none += entry.second;
  for (const auto& entry : some.adds) adds_some += entry.second;
  EXPECT_LT(adds_some, adds_none);
  EXPECT_EQ(none.stats.images_reused, 0u);
  // In use: the current and next chunk, at most 4 blocks of 5.
  EXPECT_LE(some.max_held, 25u + 20u);
  EXPECT_LE(none.max_held, 20u);
  EXPECT_EQ(some.results, none.results);
  std::cout << "60 images, blocks of 5, groups of 2 blocks: " << adds_none << " adds without keeping, "
            << adds_some << " keeping up to 25 images, " << kImages << " keeping all" << std::endl;
}

TEST(RetainingFeatureMatcher, DropsTheOldestReleasedFirstAndNeverOneInUse) {
  auto counting = std::make_unique<CountingMatcher>();
  CountingMatcher* inner = counting.get();
  RetainingFeatureMatcher matcher(std::move(counting), 2, [](const FeatureDescriptors&) { return 1; });
  FeatureDescriptors d;
  for (image_t id : {1, 2, 3}) matcher.AddImage(id, d);  // 3 in use, over budget: nothing to drop
  EXPECT_EQ(inner->held.size(), 3u);
  matcher.RemoveImage(2);  // released first
  matcher.RemoveImage(1);
  EXPECT_EQ(inner->held.count(2), 0u);  // dropped to get back to 2
  EXPECT_EQ(inner->held.count(1), 1u);
  matcher.AddImage(1, d);  // kept: reused, not added again
  EXPECT_EQ(inner->adds[1], 1);
  EXPECT_EQ(matcher.stats().images_reused, 1u);
  EXPECT_EQ(matcher.stats().images_dropped, 1u);
  matcher.AddImage(2, d);  // dropped before: added again
  EXPECT_EQ(inner->adds[2], 2);
}

// The wrapper has the inner matcher's traits and passes every call on,
// guides included: what a run can do does not depend on it.
TEST(RetainingFeatureMatcher, HasTheInnerTraitsAndPassesGuidesOn) {
  auto counting = std::make_unique<CountingMatcher>();
  CountingMatcher* inner = counting.get();
  RetainingFeatureMatcher matcher(std::move(counting), 2, [](const FeatureDescriptors&) { return 1; });
  EXPECT_EQ(matcher.Name(), "counting");
  EXPECT_TRUE(matcher.traits().epipolar_guidance);
  FeatureDescriptors d;
  matcher.AddImage(1, d);
  matcher.AddImage(2, d);
  matcher.Match({{1, 2}}, {EpipolarGuide{}});
  EXPECT_EQ(inner->guided_calls, 1u);
}

}  // namespace
}  // namespace cashash
