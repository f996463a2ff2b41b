// Ga-CasHash on the GPU against the CPU: the band filter of the select
// kernel (and of the per-query kernel it falls back to) must give the CPU
// cascade's matches; the guided matcher built from GPU parts must decide
// stage 1 as the CPU one does; and on a generated street (keypoints and
// descriptors shaped like real ones, generated_street_pairs.h): F of each
// pair from the CPU's exhaustive matches, then CPU and GPU guided matching
// with that F. Skipped when no CUDA device is usable.
#include <gtest/gtest.h>

#include "gpu_test_support.h"

#include <array>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "cashash/pipeline/batch_verifier.h"
#include "cashash/matching/cascade_hashing.h"
#include "cashash/matchers/exact_matcher.h"
#include "cashash/matching/guided_matching.h"
#include "cashash/pipeline/matching_pipeline.h"
#include "cashash/geometry/two_view_geometry.h"
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#include "cashash_cuda/matching/guided_matching.h"
#include "generated_street_pairs.h"
#include "synthetic_guided.h"
#include "cascade_options.h"

namespace cashash {
namespace {

using testing_support::CascadeOptions;
using testing_support::GuidedScene;
using testing_support::MakeGuidedScene;
using testing_support::MakeRepeatedStructureScene;
using testing_support::MakeUnrelatedImage;

// Guided pairs: each pair with its F (the band's half-width is given per
// call).
struct GuidedPairs {
  std::vector<ImagePair> pairs;
  std::vector<std::array<double, 9>> F;

  std::vector<EpipolarGuide> Guides(double max_distance) const {
    std::vector<EpipolarGuide> guides;
    for (const std::array<double, 9>& f : F) guides.push_back(EpipolarGuide{f, max_distance});
    return guides;
  }
};

// An image as the pipeline adds it to a matcher that searches within bands:
// with its keypoints.
MatcherImage WithKeypoints(const ImageFeatures& features) {
  auto shared = std::make_shared<const ImageFeatures>(features);
  return MatcherImage{features.image_id, std::shared_ptr<const Keypoints>(shared, &shared->keypoints),
                      std::shared_ptr<const FeatureDescriptors>(shared, &shared->descriptors)};
}

// Matches of a and b that differ, counted both ways.
size_t Differences(const FeatureMatches& a, const FeatureMatches& b) {
  size_t common = 0, i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (a[i] == b[j]) {
      ++common;
      ++i;
      ++j;
    } else if (a[i] < b[j]) {
      ++i;
    } else {
      ++j;
    }
  }
  return a.size() + b.size() - 2 * common;
}

// CPU and GPU guided matching of the same pairs; the band test is the same
// double arithmetic on both, so only a point within rounding of the band's
// edge could differ.
void ExpectSameGuidedMatches(const std::vector<const ImageFeatures*>& images, const GuidedPairs& guided,
                             double max_distance, const char* kernel) {
  const std::vector<ImagePair>& pairs = guided.pairs;
  std::vector<const FeatureDescriptors*> descriptors;
  for (const ImageFeatures* f : images) descriptors.push_back(&f->descriptors);
  const MeanDescriptor mean = ComputeMeanDescriptor(descriptors);
  const SiftMatchingOptions sift;
  const CasHashOptions cashash = CascadeOptions();
  auto cpu = CreateCpuFeatureMatcher(sift, cashash, mean);
  cuda::GpuMatcherConfig config;
  config.cascade_kernel = kernel != nullptr && std::string(kernel) == "direct" ? cuda::GpuCascadeKernel::kPerQuery
                                                                              : cuda::GpuCascadeKernel::kBucketTiles;
  auto gpu = cuda::CreateGpuFeatureMatcher(sift, cashash, mean, config);
  ASSERT_TRUE(gpu->traits().epipolar_guidance);
  for (size_t k = 0; k < images.size(); ++k) {
    cpu->AddImage(WithKeypoints(*images[k]));
    gpu->AddImage(WithKeypoints(*images[k]));
  }
  const std::vector<FeatureMatches> want = cpu->Match(pairs, guided.Guides(max_distance));
  const std::vector<FeatureMatches> got = gpu->Match(pairs, guided.Guides(max_distance));
  ASSERT_EQ(got.size(), pairs.size());
  size_t total = 0, differ = 0;
  for (size_t k = 0; k < pairs.size(); ++k) {
    total += want[k].size();
    differ += Differences(want[k], got[k]);
  }
  std::printf("[ guided ] %s kernel, d = %.1f: %zu pairs, %zu CPU matches, %zu differ on the GPU\n",
              kernel != nullptr ? kernel : "tiled", max_distance, pairs.size(), total, differ);
  EXPECT_GT(total, 0u);
  EXPECT_LE(differ, total / 1000) << "GPU guided matching differs from the CPU's";
}

struct SyntheticPairs {
  std::vector<GuidedScene> scenes;
  std::vector<ImageFeatures> images;
};

// Three scenes (6 images), matched as 3 guided pairs plus one pair listed
// twice, so that images' keypoints are shared between tasks.
SyntheticPairs MakeSyntheticPairs(GuidedPairs* pairs) {
  SyntheticPairs s;
  for (unsigned seed : {31u, 32u, 33u}) s.scenes.push_back(MakeGuidedScene(2000, seed));
  for (size_t k = 0; k < s.scenes.size(); ++k) {
    s.images.push_back(s.scenes[k].image1);
    s.images.back().image_id = static_cast<image_t>(2 * k + 1);
    s.images.push_back(s.scenes[k].image2);
    s.images.back().image_id = static_cast<image_t>(2 * k + 2);
  }
  for (size_t k = 0; k < s.scenes.size(); ++k) {
    pairs->pairs.push_back({static_cast<image_t>(2 * k + 1), static_cast<image_t>(2 * k + 2)});
    pairs->F.push_back(s.scenes[k].F);
  }
  pairs->pairs.push_back(pairs->pairs.front());
  pairs->F.push_back(pairs->F.front());
  return s;
}

TEST(GpuGuidedMatching, SameMatchesAsTheCpuOnSyntheticScenes) {
  SKIP_WITHOUT_CUDA_DEVICE();
  GuidedPairs pairs;
  const SyntheticPairs s = MakeSyntheticPairs(&pairs);
  std::vector<const ImageFeatures*> images;
  for (const ImageFeatures& f : s.images) images.push_back(&f);
  for (const double d : {2.0, 8.0}) {
    ExpectSameGuidedMatches(images, pairs, d, nullptr);
    ExpectSameGuidedMatches(images, pairs, d, "direct");
  }
}

TEST(GpuGuidedMatching, UnboundedBandEqualsUnguidedMatching) {
  SKIP_WITHOUT_CUDA_DEVICE();
  GuidedPairs pairs;
  const SyntheticPairs s = MakeSyntheticPairs(&pairs);
  std::vector<const FeatureDescriptors*> descriptors;
  for (const ImageFeatures& f : s.images) descriptors.push_back(&f.descriptors);
  const MeanDescriptor mean = ComputeMeanDescriptor(descriptors);
  auto gpu = cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), CascadeOptions(), mean, 0);
  for (const ImageFeatures& f : s.images) gpu->AddImage(WithKeypoints(f));
  EXPECT_EQ(gpu->Match(pairs.pairs, pairs.Guides(1e9)), gpu->Match(pairs.pairs));
  // Too few positions for an image is refused, as is none.
  ImageFeatures few = s.images[1];
  few.keypoints.resize(5);
  gpu->AddImage(WithKeypoints(few));
  EXPECT_THROW(gpu->Match(pairs.pairs, pairs.Guides(4.0)), std::invalid_argument);
  gpu->AddImage(few.image_id, few.descriptors);
  EXPECT_THROW(gpu->Match(pairs.pairs, pairs.Guides(4.0)), std::invalid_argument);
}

// Images 1 and 2 of a scene and an unrelated image 3, served to a guided
// matcher built from GPU parts.
struct GpuGuidedRig {
  struct Source : FeatureSource {
    std::vector<ImageFeatures> images;
    Camera camera;
    ImageFeatures LoadFeatures(image_t id) override { return images[id - 1]; }
    const Camera& CameraOfImage(image_t) const override { return camera; }
  } source;
  std::unique_ptr<GuidedFeatureMatcher> matcher;

  GpuGuidedRig(const GuidedScene& scene, const GuidedMatchingOptions& options) {
    source.images = {scene.image1, scene.image2, MakeUnrelatedImage(1500, 22)};
    const MeanDescriptor mean =
        ComputeMeanDescriptor({&source.images[0].descriptors, &source.images[1].descriptors});
    const SiftMatchingOptions sift;
    const CasHashOptions cashash = CascadeOptions();
    matcher = std::make_unique<GuidedFeatureMatcher>(
        cuda::CreateGpuFeatureMatcher(sift, cashash, mean, 0), cuda::CreateGpuFeatureMatcher(sift, cashash, mean, 0),
        cuda::CreateGpuFundamentalEstimator(TwoViewGeometryOptions(), 0), options, 32768, 0, -1);
    for (image_t id : {1u, 2u, 3u}) {
      ImageFeatures features = source.LoadFeatures(id);
      features.image_id = id;
      matcher->AddImage(WithKeypoints(features));
    }
  }
};

TEST(GpuGuidedMatching, GuidedMatcherFromGpuPartsDecidesAsTheCpuOne) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const GuidedScene scene = MakeGuidedScene(1500, 21);
  for (const bool search_in_band : {false, true}) {
    GuidedMatchingOptions options;
    options.restrict_search_to_band = search_in_band;
    GpuGuidedRig rig(scene, options);
    EXPECT_NE(rig.matcher->Name().find("gpu-cascade"), std::string::npos);
    const std::vector<FeatureMatches> result = rig.matcher->Match({{1, 2}, {1, 3}, {3, 2}});
    EXPECT_EQ(rig.matcher->last_outcomes()[0], GuidedStage1Outcome::kGuided);
    EXPECT_EQ(rig.matcher->last_outcomes()[1], GuidedStage1Outcome::kTooFewMatches);
    EXPECT_EQ(rig.matcher->last_outcomes()[2], GuidedStage1Outcome::kTooFewMatches);
    EXPECT_TRUE(result[1].empty());
    EXPECT_TRUE(result[2].empty());
    size_t right = 0;
    for (const FeatureMatch& m : result[0]) right += scene.truth[m.point2D_idx1] == static_cast<int>(m.point2D_idx2);
    // The band search also recovers the features whose decoy lies off the
    // line; exact matches filtered by the band do not (tests/matching/guided_matching_test.cc).
    EXPECT_GT(result[0].size(), search_in_band ? 1100u : 900u) << "search_in_band " << search_in_band;
    EXPECT_GE(right, result[0].size() * 99 / 100);
  }
}

TEST(GpuGuidedMatching, RejectsRepeatedStructureOnTheEpipolarLine) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const GuidedScene scene = MakeRepeatedStructureScene(1500, 23);
  GpuGuidedRig rig(scene, GuidedMatchingOptions());
  const FeatureMatches guided = rig.matcher->Match({{1, 2}})[0];
  ASSERT_EQ(rig.matcher->last_outcomes()[0], GuidedStage1Outcome::kGuided);
  size_t right = 0, on_line = 0;
  for (const FeatureMatch& m : guided) {
    right += scene.truth[m.point2D_idx1] == static_cast<int>(m.point2D_idx2);
    on_line += scene.decoy[m.point2D_idx1] == static_cast<int>(m.point2D_idx2);
  }
  EXPECT_EQ(on_line, 0u);
  EXPECT_EQ(right, guided.size());
  EXPECT_GT(right, 750u);
}

TEST(GpuGuidedMatching, SameMatchesAsTheCpuOnAGeneratedStreet) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const testing_support::ScratchDir dir("gpu_guided_street");
  const std::vector<ImageFeatures> images = testing_support::GenerateStreet(dir, 6, 4000, 7).images;
  ASSERT_EQ(images.size(), 6u);
  std::vector<const FeatureDescriptors*> descriptors;
  for (const ImageFeatures& f : images) descriptors.push_back(&f.descriptors);
  const MeanDescriptor mean = ComputeMeanDescriptor(descriptors);
  auto cpu = CreateCpuFeatureMatcher(SiftMatchingOptions(), CascadeOptions(), mean);
  for (size_t k = 0; k < images.size(); ++k) cpu->AddImage(images[k].image_id, images[k].descriptors);
  // F of every pair from the CPU's exhaustive matches.
  GuidedPairs pairs;
  for (size_t a = 0; a < images.size(); ++a) {
    for (size_t b = a + 1; b < images.size(); ++b) {
      const ImagePair pair{images[a].image_id, images[b].image_id};
      const FeatureMatches matches = cpu->Match({pair})[0];
      if (matches.size() < 16) continue;
      const TwoViewPoints points = PrepareTwoViewPoints(KeypointPositions(images[a].keypoints),
                                                        KeypointPositions(images[b].keypoints), matches);
      const TwoViewModelEstimate F = EstimateFundamental(points, TwoViewGeometryOptions());
      if (!F.success) continue;
      std::array<double, 9> f{};
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) f[3 * r + c] = F.model(r, c);
      pairs.pairs.push_back(pair);
      pairs.F.push_back(f);
    }
  }
  ASSERT_FALSE(pairs.pairs.empty());
  std::vector<const ImageFeatures*> pointers;
  for (const ImageFeatures& f : images) pointers.push_back(&f);
  for (const double d : {4.0, 8.0}) {
    ExpectSameGuidedMatches(pointers, pairs, d, nullptr);
    ExpectSameGuidedMatches(pointers, pairs, d, "direct");
  }
}

}  // namespace
}  // namespace cashash
