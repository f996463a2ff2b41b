#include "cashash/matchers/fallback_feature_matcher.h"

#include <memory>
#include <random>
#include <stdexcept>

#include <gtest/gtest.h>

#include "cashash/base/device_memory_error.h"
#include "synthetic_sift.h"
#include "cascade_options.h"

namespace cashash {
namespace {

using testing_support::CascadeOptions;

// Stands in for the GPU backend: wraps a CPU matcher and throws the given
// error at the n-th call (AddImage, Match and MatchExact counted together).
class FailingMatcher : public MatchingBackend {
 public:
  // Throws DeviceMemoryError(message), or with `device_memory` false a
  // plain std::runtime_error, at call `fail_at_call`.
  FailingMatcher(std::unique_ptr<MatchingBackend> inner, int fail_at_call, std::string message,
                 bool device_memory = true)
      : MatchingBackend(MatcherTraits{"failing-gpu", true}),
        inner_(std::move(inner)),
        fail_at_call_(fail_at_call),
        message_(std::move(message)),
        device_memory_(device_memory) {}
  void AddImage(const Image& image) override {
    MaybeFail();
    inner_->AddImage(image);
  }
  void RemoveImage(image_t id) override { inner_->RemoveImage(id); }
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& guides = {}) override {
    MaybeFail();
    return inner_->Match(pairs, guides);
  }
  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override {
    MaybeFail();
    return inner_->MatchExact(pairs);
  }
  std::unique_ptr<ExactMatcher> HoldForExact(const std::vector<ImagePair>& pairs) override {
    return inner_->HoldForExact(pairs);
  }

 private:
  void MaybeFail() {
    if (++calls_ != fail_at_call_) return;
    if (device_memory_) throw DeviceMemoryError(message_);
    throw std::runtime_error(message_);
  }
  std::unique_ptr<MatchingBackend> inner_;
  int calls_ = 0;
  int fail_at_call_;
  std::string message_;
  bool device_memory_;
};

struct Scene {
  std::vector<FeatureDescriptors> images;
  std::vector<ImagePair> pairs;
  MeanDescriptor mean{};
};

Scene MakeScene() {
  std::mt19937 rng(3);
  Scene scene;
  std::vector<std::vector<uint8_t>> base;
  for (int k = 0; k < 300; ++k) base.push_back(testing_support::RandomSift(&rng));
  std::uniform_int_distribution<int> noise(-3, 3);
  for (int i = 0; i < 5; ++i) {
    FeatureDescriptors d;
    for (const std::vector<uint8_t>& b : base) {
      for (uint8_t x : b) d.data.push_back(static_cast<uint8_t>(std::clamp(int(x) + noise(rng), 0, 255)));
    }
    scene.images.push_back(std::move(d));
  }
  for (image_t i = 0; i < 5; ++i)
    for (image_t j = i + 1; j < 5; ++j) scene.pairs.emplace_back(i, j);
  std::vector<const FeatureDescriptors*> pointers;
  for (const FeatureDescriptors& d : scene.images) pointers.push_back(&d);
  scene.mean = ComputeMeanDescriptor(pointers);
  return scene;
}

std::vector<FeatureMatches> AddAndMatch(FeatureMatcher* matcher, const Scene& scene) {
  for (size_t i = 0; i < scene.images.size(); ++i) matcher->AddImage(static_cast<image_t>(i), scene.images[i]);
  matcher->RemoveImage(4);
  matcher->AddImage(4, scene.images[4]);
  return matcher->Match(scene.pairs);
}

std::unique_ptr<MatchingBackend> Cpu(const Scene& scene) {
  return CreateCpuFeatureMatcher(SiftMatchingOptions(), CascadeOptions(), scene.mean);
}

TEST(FallbackFeatureMatcher, DeviceMemoryErrorsMoveTheRunToTheFallback) {
  const Scene scene = MakeScene();
  const std::vector<FeatureMatches> expected = AddAndMatch(Cpu(scene).get(), scene);
  size_t total = 0;
  for (const FeatureMatches& m : expected) total += m.size();
  ASSERT_GT(total, 100u);
  // Fail while adding images (call 3) and while matching (call 7).
  for (int fail_at : {3, 7}) {
    std::vector<std::string> warnings;
    auto matcher = CreateFallbackFeatureMatcher(
        std::make_unique<FailingMatcher>(Cpu(scene), fail_at, "GPU out of memory allocating 2 MiB for image 2"),
        [&] { return Cpu(scene); }, IsDeviceMemoryError,
        [&](const std::string& text) { warnings.push_back(text); });
    // The traits are the primary's, fixed when it is built.
    EXPECT_EQ(matcher->Name(), "failing-gpu");
    EXPECT_TRUE(matcher->traits().epipolar_guidance);
    EXPECT_EQ(AddAndMatch(matcher.get(), scene), expected) << "fail at call " << fail_at;
    EXPECT_EQ(matcher->Name(), "failing-gpu");
    // One warning, naming the backend that failed, its error and the one
    // that goes on.
    ASSERT_EQ(warnings.size(), 1u);
    EXPECT_NE(warnings[0].find("failing-gpu"), std::string::npos) << warnings[0];
    EXPECT_NE(warnings[0].find("GPU out of memory allocating 2 MiB for image 2"), std::string::npos) << warnings[0];
    EXPECT_NE(warnings[0].find(Cpu(scene)->Name()), std::string::npos) << warnings[0];
  }
}

// The pipeline shares its features with the matcher: the fallback keeps
// that handle (no copy) until the image is removed, and rebuilds from it.
TEST(FallbackFeatureMatcher, SharedImagesAreKeptWithoutACopyAndRebuiltFrom) {
  const Scene scene = MakeScene();
  const std::vector<FeatureMatches> expected = AddAndMatch(Cpu(scene).get(), scene);
  std::vector<std::shared_ptr<const FeatureDescriptors>> shared;
  for (const FeatureDescriptors& d : scene.images) shared.push_back(std::make_shared<const FeatureDescriptors>(d));
  // Fails at the first MatchPairs (call 6: five adds first).
  auto matcher = CreateFallbackFeatureMatcher(
      std::make_unique<FailingMatcher>(Cpu(scene), 6, "GPU out of memory allocating 2 MiB for codes"),
      [&] { return Cpu(scene); }, IsDeviceMemoryError, nullptr);
  for (size_t i = 0; i < shared.size(); ++i) matcher->AddImage(MatcherImage{static_cast<image_t>(i), nullptr, shared[i]});
  for (const auto& handle : shared) EXPECT_EQ(handle.use_count(), 2) << "held once by the fallback, not copied";
  matcher->RemoveImage(4);
  EXPECT_EQ(shared[4].use_count(), 1) << "released with the image";
  matcher->AddImage(MatcherImage{4, nullptr, shared[4]});
  EXPECT_EQ(matcher->Match(scene.pairs), expected);  // rebuilt on the CPU from the handles
}

// Exact matching goes through the same guard: out of memory there moves
// the run to the fallback too, which gives the same exact matches.
TEST(FallbackFeatureMatcher, ExactMatchingFallsBackAsMatchingDoes) {
  const Scene scene = MakeScene();
  auto cpu = Cpu(scene);
  for (size_t i = 0; i < scene.images.size(); ++i) cpu->AddImage(static_cast<image_t>(i), scene.images[i]);
  const std::vector<FeatureMatches> expected = cpu->MatchExact(scene.pairs);
  std::vector<std::string> warnings;
  // Fails at the first MatchExact (call 6: five adds first).
  auto matcher = CreateFallbackFeatureMatcher(
      std::make_unique<FailingMatcher>(Cpu(scene), 6, "GPU out of memory allocating scratch"),
      [&] { return Cpu(scene); }, IsDeviceMemoryError, [&](const std::string& text) { warnings.push_back(text); });
  for (size_t i = 0; i < scene.images.size(); ++i) matcher->AddImage(static_cast<image_t>(i), scene.images[i]);
  EXPECT_EQ(matcher->MatchExact(scene.pairs), expected);
  EXPECT_EQ(warnings.size(), 1u);
  // What it holds afterwards is the fallback's.
  EXPECT_EQ(matcher->HoldForExact(scene.pairs)->MatchExact(scene.pairs), expected);
}

TEST(FallbackFeatureMatcher, OtherErrorsPropagate) {
  const Scene scene = MakeScene();
  auto matcher = CreateFallbackFeatureMatcher(std::make_unique<FailingMatcher>(Cpu(scene), 2, "kernel launch failed", false),
                                              [&] { return Cpu(scene); }, IsDeviceMemoryError, nullptr);
  EXPECT_THROW(AddAndMatch(matcher.get(), scene), std::runtime_error);
}

// By its type, not its text: a message that merely mentions memory is not
// a device memory error, and any DeviceMemoryError is.
TEST(FallbackFeatureMatcher, RecognisesDeviceMemoryErrorsByTheirType) {
  EXPECT_TRUE(IsDeviceMemoryError(DeviceMemoryError("GPU memory budget exceeded by image 11: it needs 2 MiB")));
  EXPECT_TRUE(IsDeviceMemoryError(DeviceMemoryError("cascade.cu:10: cudaMalloc failed")));
  EXPECT_FALSE(IsDeviceMemoryError(std::runtime_error("cascade.cu:10: cudaMalloc: out of memory")));
  EXPECT_FALSE(IsDeviceMemoryError(std::runtime_error("invalid device function")));
}

}  // namespace
}  // namespace cashash
