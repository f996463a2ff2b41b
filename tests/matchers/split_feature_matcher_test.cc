// Several matchers behind one (one per GPU): same results in the same order
// as one matcher, every part gets every image and a contiguous slice of
// each call's pairs, and a part's error reaches the caller.
#include "cashash/matchers/split_feature_matcher.h"

#include <algorithm>
#include <mutex>
#include <random>
#include <set>
#include <stdexcept>
#include <thread>

#include <gtest/gtest.h>

#include "synthetic_sift.h"
#include "cascade_options.h"

namespace cashash {
namespace {

using testing_support::CascadeOptions;

struct Scene {
  std::vector<FeatureDescriptors> images;
  std::vector<ImagePair> pairs;
  MeanDescriptor mean{};
};

Scene MakeScene(int num_images) {
  std::mt19937 rng(5);
  Scene scene;
  std::vector<std::vector<uint8_t>> base;
  for (int k = 0; k < 200; ++k) base.push_back(testing_support::RandomSift(&rng));
  std::uniform_int_distribution<int> noise(-3, 3);
  for (int i = 0; i < num_images; ++i) {
    FeatureDescriptors d;
    for (const std::vector<uint8_t>& b : base) {
      for (uint8_t x : b) d.data.push_back(static_cast<uint8_t>(std::clamp(int(x) + noise(rng), 0, 255)));
    }
    scene.images.push_back(std::move(d));
  }
  for (int i = 0; i < num_images; ++i)
    for (int j = i + 1; j < num_images; ++j) scene.pairs.emplace_back(image_t(i), image_t(j));
  std::vector<const FeatureDescriptors*> pointers;
  for (const FeatureDescriptors& d : scene.images) pointers.push_back(&d);
  scene.mean = ComputeMeanDescriptor(pointers);
  return scene;
}

// Records what it is asked, on which thread, and answers through a CPU matcher.
class RecordingMatcher : public MatchingBackend {
 public:
  RecordingMatcher(std::unique_ptr<MatchingBackend> inner, bool fail)
      : MatchingBackend(MatcherTraits{"recording", true}), inner_(std::move(inner)), fail_(fail) {}
  void AddImage(const Image& image) override {
    images.insert(image.id);
    inner_->AddImage(image);
  }
  using FeatureMatcher::AddImage;
  void RemoveImage(image_t id) override {
    images.erase(id);
    inner_->RemoveImage(id);
  }
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& guides = {}) override {
    Record(pairs);
    guided_calls += guides.empty() ? 0 : 1;
    return inner_->Match(pairs, guides);
  }
  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override {
    Record(pairs);
    return inner_->MatchExact(pairs);
  }
  std::unique_ptr<ExactMatcher> HoldForExact(const std::vector<ImagePair>& pairs) override {
    ++holds;
    return inner_->HoldForExact(pairs);
  }

  std::set<image_t> images;
  std::vector<std::vector<ImagePair>> calls;
  std::set<std::thread::id> threads;
  size_t guided_calls = 0;
  size_t holds = 0;

 private:
  void Record(const std::vector<ImagePair>& pairs) {
    calls.push_back(pairs);
    threads.insert(std::this_thread::get_id());
    if (fail_) throw std::runtime_error("device 1 failed");
  }
  std::unique_ptr<MatchingBackend> inner_;
  bool fail_;
};

std::unique_ptr<MatchingBackend> Cpu(const Scene& scene) {
  return CreateCpuFeatureMatcher(SiftMatchingOptions(), CascadeOptions(), scene.mean);
}

TEST(SplitFeatureMatcher, SlicesCoverEveryItemOnceWithSizesWithinOne) {
  for (size_t count : {0u, 1u, 5u, 7u, 100u}) {
    for (size_t n : {1u, 2u, 3u, 8u}) {
      size_t next = 0, smallest = count, largest = 0;
      for (size_t k = 0; k < n; ++k) {
        size_t begin = 0, end = 0;
        SliceBounds(count, k, n, &begin, &end);
        EXPECT_EQ(begin, next);
        next = end;
        smallest = std::min(smallest, end - begin);
        largest = std::max(largest, end - begin);
      }
      EXPECT_EQ(next, count);
      EXPECT_LE(largest - smallest, 1u);
    }
  }
}

// A split over three recording CPU backends of `scene`; `recorders` gets
// the parts, in order.
std::unique_ptr<SplitFeatureMatcher> SplitOfThreeRecorders(const Scene& scene,
                                                           std::vector<RecordingMatcher*>* recorders) {
  std::vector<std::unique_ptr<MatchingBackend>> parts;
  for (int k = 0; k < 3; ++k) {
    auto part = std::make_unique<RecordingMatcher>(Cpu(scene), false);
    recorders->push_back(part.get());
    parts.push_back(std::move(part));
  }
  return std::make_unique<SplitFeatureMatcher>(std::move(parts));
}

TEST(SplitFeatureMatcher, SameMatchesInTheSameOrderAsOneMatcher) {
  const Scene scene = MakeScene(7);  // 21 pairs
  auto single = Cpu(scene);
  std::vector<RecordingMatcher*> recorders;
  const std::unique_ptr<SplitFeatureMatcher> split_owner = SplitOfThreeRecorders(scene, &recorders);
  SplitFeatureMatcher& split = *split_owner;
  EXPECT_EQ(split.num_parts(), 3u);
  EXPECT_EQ(split.Name(), "recording x3");
  for (size_t i = 0; i < scene.images.size(); ++i) {
    single->AddImage(image_t(i), scene.images[i]);
    split.AddImage(image_t(i), scene.images[i]);
  }
  split.RemoveImage(6);
  split.AddImage(6, scene.images[6]);
  const std::vector<FeatureMatches> expected = single->Match(scene.pairs);
  const std::vector<FeatureMatches> got = split.Match(scene.pairs);
  size_t total = 0;
  for (const FeatureMatches& m : expected) total += m.size();
  EXPECT_GT(total, 0u);
  EXPECT_EQ(got, expected);

  // Every part holds every image and got one contiguous slice of 7 pairs.
  std::set<std::thread::id> threads;
  size_t next = 0;
  for (RecordingMatcher* r : recorders) {
    EXPECT_EQ(r->images.size(), scene.images.size());
    ASSERT_EQ(r->calls.size(), 1u);
    ASSERT_EQ(r->calls[0].size(), 7u);
    EXPECT_EQ(r->calls[0].front(), scene.pairs[next]);
    next += r->calls[0].size();
    threads.insert(r->threads.begin(), r->threads.end());
  }
  EXPECT_EQ(threads.size(), 3u);  // the slices ran on three threads

  // Calls with fewer than two pairs per part stay on the first part.
  const std::vector<ImagePair> few(scene.pairs.begin(), scene.pairs.begin() + 5);
  EXPECT_EQ(split.Match(few), single->Match(few));
  EXPECT_EQ(recorders[0]->calls.size(), 2u);
  EXPECT_EQ(recorders[1]->calls.size(), 1u);
}

// Exact matching, now or from held images, is shared out as matching is,
// and gives the single backend's exact matches in the callers' order.
TEST(SplitFeatureMatcher, ExactMatchingIsSharedOutAsMatchingIs) {
  const Scene scene = MakeScene(7);  // 21 pairs
  auto single = Cpu(scene);
  std::vector<RecordingMatcher*> recorders;
  const std::unique_ptr<SplitFeatureMatcher> split_owner = SplitOfThreeRecorders(scene, &recorders);
  SplitFeatureMatcher& split = *split_owner;
  EXPECT_TRUE(split.traits().epipolar_guidance);
  for (size_t i = 0; i < scene.images.size(); ++i) {
    single->AddImage(image_t(i), scene.images[i]);
    split.AddImage(image_t(i), scene.images[i]);
  }
  const std::vector<FeatureMatches> expected = single->MatchExact(scene.pairs);
  EXPECT_EQ(split.MatchExact(scene.pairs), expected);
  for (RecordingMatcher* r : recorders) ASSERT_EQ(r->calls.size(), 1u);
  std::unique_ptr<ExactMatcher> held = split.HoldForExact(scene.pairs);
  for (size_t i = 0; i < scene.images.size(); ++i) split.RemoveImage(image_t(i));
  std::vector<FeatureMatches> later;
  std::thread([&] { later = held->MatchExact(scene.pairs); }).join();
  EXPECT_EQ(later, expected);
  for (RecordingMatcher* r : recorders) EXPECT_EQ(r->holds, 1u);
}

TEST(SplitFeatureMatcher, AnErrorOfOnePartReachesTheCaller) {
  const Scene scene = MakeScene(5);
  std::vector<std::unique_ptr<MatchingBackend>> parts;
  parts.push_back(std::make_unique<RecordingMatcher>(Cpu(scene), false));
  parts.push_back(std::make_unique<RecordingMatcher>(Cpu(scene), true));
  SplitFeatureMatcher split(std::move(parts));
  for (size_t i = 0; i < scene.images.size(); ++i) split.AddImage(image_t(i), scene.images[i]);
  EXPECT_THROW(
      {
        try {
          split.Match(scene.pairs);
        } catch (const std::runtime_error& e) {
          EXPECT_STREQ(e.what(), "device 1 failed");
          throw;
        }
      },
      std::runtime_error);
  EXPECT_THROW(SplitFeatureMatcher(std::vector<std::unique_ptr<MatchingBackend>>{}), std::invalid_argument);
}

}  // namespace
}  // namespace cashash
