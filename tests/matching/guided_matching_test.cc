// Ga-CasHash on the CPU: the epipolar band (epipolar_band.h), the band
// filter inside the cascade, the top-scale subsets, the stage-1 decision and
// the two-stage GuidedFeatureMatcher (guided_matching.h).
#include "cashash/matching/guided_matching.h"
#include "cashash/pipeline/matching_pipeline.h"

#include <gtest/gtest.h>

#include <map>
#include <stdexcept>

#include "cashash/matching/cascade_matcher.h"
#include "cashash/matching/epipolar_band.h"
#include "cashash/matchers/exact_matcher.h"
#include "synthetic_guided.h"
#include "cascade_options.h"

namespace cashash {
namespace {

using testing_support::CascadeOptions;
using testing_support::GuidedScene;
using testing_support::MakeGuidedScene;
using testing_support::MakeRepeatedStructureScene;
using testing_support::MakeUnrelatedImage;

// Camera 2 translated along x: F = [e]x with e = (1, 0, 0); the epipolar
// lines are the rows y' = y in both images.
const double kRowsF[9] = {0, 0, 0, 0, 0, -1, 0, 1, 0};

TEST(EpipolarBand, DistanceToTheLineInPixels) {
  const EpipolarLine in2 = LineInSecondImage(kRowsF, 10.f, 100.f);
  ASSERT_FALSE(in2.everywhere);
  EXPECT_NEAR(std::abs(in2.a * 500 + in2.b * 103 + in2.c), 3.0, 1e-12);
  EXPECT_TRUE(in2.Contains(500.f, 103.f, 3.0));
  EXPECT_FALSE(in2.Contains(500.f, 103.f, 2.99));
  EXPECT_TRUE(in2.Contains(-4000.f, 97.5f, 2.6));  // anywhere along the row
  const EpipolarLine in1 = LineInFirstImage(kRowsF, 700.f, 50.f);
  EXPECT_TRUE(in1.Contains(3.f, 52.f, 2.0));
  EXPECT_FALSE(in1.Contains(3.f, 52.5f, 2.0));
}

TEST(EpipolarBand, LineInFirstImageIsTheTransposedRelation) {
  const GuidedScene scene = MakeGuidedScene(50, 3);
  for (int i = 0; i < 50; ++i) {
    const Keypoint& p1 = scene.image1.keypoints[i];
    const Keypoint& p2 = scene.image2.keypoints[scene.truth[i]];
    // Both distances of a true correspondence are within the noise.
    EXPECT_TRUE(LineInSecondImage(scene.F.data(), p1.x, p1.y).Contains(p2.x, p2.y, 3.0)) << i;
    EXPECT_TRUE(LineInFirstImage(scene.F.data(), p2.x, p2.y).Contains(p1.x, p1.y, 3.0)) << i;
  }
}

TEST(EpipolarBand, NoLineMeansNoConstraint) {
  const double zero[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
  EXPECT_TRUE(LineInSecondImage(zero, 1.f, 2.f).everywhere);
  EXPECT_TRUE(LineInSecondImage(zero, 1.f, 2.f).Contains(1e6f, -1e6f, 0.5));
  // The epipole itself: F e1 = 0 for e1 = (x, y, 1) on the null vector.
  const double at_origin[9] = {0, 0, 0, 0, 0, -1, 0, 1, 0};
  EXPECT_FALSE(LineInSecondImage(at_origin, 5.f, 0.f).everywhere);
  const double nan_f[9] = {std::nan(""), 0, 0, 0, 0, 0, 0, 0, 0};
  EXPECT_TRUE(LineInSecondImage(nan_f, 1.f, 2.f).everywhere);
}

TEST(TopScaleFeatures, KeepsTheLargestScalesInRowOrder) {
  Keypoints kps;
  const float scales[] = {1, 9, 3, 7, 7, 2, 8, 1, 5, 4};
  for (float s : scales) kps.push_back(testing_support::MakeKeypoint(Eigen::Vector2d(0, 0), s));
  EXPECT_EQ(SelectTopScaleFeatures(kps, 10, 0.2), (std::vector<uint32_t>{1, 6}));
  // ceil(0.3 * 10) = 3; the tie at 7 goes to the lower row.
  EXPECT_EQ(SelectTopScaleFeatures(kps, 10, 0.3), (std::vector<uint32_t>{1, 3, 6}));
  EXPECT_EQ(SelectTopScaleFeatures(kps, 10, 0.25), (std::vector<uint32_t>{1, 3, 6}));
  // Only the first num_rows take part; at least one row.
  EXPECT_EQ(SelectTopScaleFeatures(kps, 4, 0.2), (std::vector<uint32_t>{1}));
  EXPECT_EQ(SelectTopScaleFeatures(kps, 10, 1.0).size(), 10u);
  EXPECT_TRUE(SelectTopScaleFeatures(kps, 0, 0.2).empty());
}

TEST(TopScaleFeatures, ScaleIsTheAffineShapeDeterminant) {
  Keypoint k;
  const float angle = 0.7f, s = 3.f;
  k.a11 = s * std::cos(angle);
  k.a12 = -s * std::sin(angle);
  k.a21 = s * std::sin(angle);
  k.a22 = s * std::cos(angle);
  EXPECT_NEAR(KeypointScale(k), 3.f, 1e-5f);
  EXPECT_NEAR(KeypointScale(k), k.ComputeScale(), 1e-5f);  // COLMAP's, for similarity shapes
  k.a11 = 2;
  k.a12 = 0;
  k.a21 = 0;
  k.a22 = 8;  // anisotropic: geometric mean of the axes
  EXPECT_NEAR(KeypointScale(k), 4.f, 1e-6f);
}

TEST(GuidedStage1, ThresholdsOfThePaper) {
  GuidedMatchingOptions options;  // 16 matches, 2/3 inliers
  options.unguided_fallback = false;
  TwoViewModelEstimate F;
  F.success = true;
  F.num_inliers = 15;
  EXPECT_EQ(DecideGuidedStage1(15, &F, options), GuidedStage1Outcome::kTooFewMatches);
  F.num_inliers = 16;
  EXPECT_EQ(DecideGuidedStage1(24, &F, options), GuidedStage1Outcome::kGuided);  // exactly 2/3
  F.num_inliers = 15;
  EXPECT_EQ(DecideGuidedStage1(24, &F, options), GuidedStage1Outcome::kFewInliers);
  F.num_inliers = 16;
  EXPECT_EQ(DecideGuidedStage1(16, &F, options), GuidedStage1Outcome::kGuided);
  F.success = false;
  EXPECT_EQ(DecideGuidedStage1(100, &F, options), GuidedStage1Outcome::kFewInliers);
  EXPECT_EQ(DecideGuidedStage1(100, nullptr, options), GuidedStage1Outcome::kFewInliers);
}

TEST(GuidedStage1, WeakPairsGoToTheFallback) {
  const GuidedMatchingOptions options;  // fallback on, from 8 stage-1 matches
  EXPECT_TRUE(options.unguided_fallback);
  EXPECT_EQ(options.fallback_min_num_matches, 8);
  EXPECT_EQ(DecideGuidedStage1(7, nullptr, options), GuidedStage1Outcome::kTooFewMatches);
  EXPECT_EQ(DecideGuidedStage1(8, nullptr, options), GuidedStage1Outcome::kNoModel);
  EXPECT_EQ(DecideGuidedStage1(15, nullptr, options), GuidedStage1Outcome::kNoModel);
  EXPECT_EQ(DecideGuidedStage1(16, nullptr, options), GuidedStage1Outcome::kFewInliers);
}

TEST(GuidedMatchingOptions, CheckNamesTheOption) {
  GuidedMatchingOptions o;
  EXPECT_EQ(o.Check(), "");
  EXPECT_DOUBLE_EQ(o.top_scale_fraction, 0.2);
  EXPECT_EQ(o.min_num_matches, 16);
  EXPECT_DOUBLE_EQ(o.min_inlier_ratio, 2.0 / 3.0);
  o.top_scale_fraction = 0;
  EXPECT_NE(o.Check().find("top_scale_fraction"), std::string::npos);
  o = GuidedMatchingOptions();
  o.min_num_matches = 5;
  EXPECT_NE(o.Check().find("min_num_matches"), std::string::npos);
  o = GuidedMatchingOptions();
  o.min_inlier_ratio = 1.5;
  EXPECT_NE(o.Check().find("min_inlier_ratio"), std::string::npos);
  o = GuidedMatchingOptions();
  o.fallback_min_num_matches = 0;
  EXPECT_NE(o.Check().find("fallback_min_num_matches"), std::string::npos);
  o.fallback_min_num_matches = 17;  // above min_num_matches
  EXPECT_NE(o.Check().find("fallback_min_num_matches"), std::string::npos);
  o = GuidedMatchingOptions();
  o.max_epipolar_distance = -1;
  EXPECT_NE(o.Check().find("max_epipolar_distance"), std::string::npos);
  // 0: the default of the stage-2 method.
  o = GuidedMatchingOptions();
  EXPECT_DOUBLE_EQ(o.EpipolarDistance(), 16.0);
  o.restrict_search_to_band = true;
  EXPECT_DOUBLE_EQ(o.EpipolarDistance(), 4.0);
  o.max_epipolar_distance = 6;
  EXPECT_DOUBLE_EQ(o.EpipolarDistance(), 6.0);
}

struct HashedScene {
  CascadeImage a, b;
};

HashedScene Hash(const GuidedScene& scene, const CasHashOptions& options) {
  const CascadeProjections p = GenerateCascadeProjections(options);
  const MeanDescriptor mean = ComputeMeanDescriptor({&scene.image1.descriptors, &scene.image2.descriptors});
  return {BuildCascadeImage(scene.image1.descriptors, scene.image1.descriptors.rows(), p, mean),
          BuildCascadeImage(scene.image2.descriptors, scene.image2.descriptors.rows(), p, mean)};
}

TEST(GuidedCascade, AnUnboundedBandChangesNothing) {
  const GuidedScene scene = MakeGuidedScene(900, 11);
  const CasHashOptions options = CascadeOptions();
  const SiftMatchingOptions sift;
  const HashedScene h = Hash(scene, options);
  CascadeScratch scratch;
  const FeatureMatches plain = CascadeMatchPair(h.a, h.b, sift, options, &scratch);
  EpipolarGuidance guidance;
  guidance.F = scene.F.data();
  guidance.points1 = scene.xy1.data();
  guidance.points2 = scene.xy2.data();
  guidance.max_distance = 1e9;
  EXPECT_EQ(CascadeMatchPairGuided(h.a, h.b, guidance, sift, options, &scratch), plain);
  // F = 0 gives no line anywhere: no constraint either.
  const double zero[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
  guidance.F = zero;
  guidance.max_distance = 1;
  EXPECT_EQ(CascadeMatchPairGuided(h.a, h.b, guidance, sift, options, &scratch), plain);
}

TEST(GuidedCascade, TheBandRemovesDecoysAndRecoversTheirFeatures) {
  const GuidedScene scene = MakeGuidedScene(900, 12);
  const CasHashOptions options = CascadeOptions();
  SiftMatchingOptions sift;
  const HashedScene h = Hash(scene, options);
  CascadeScratch scratch;
  EpipolarGuidance guidance;
  guidance.F = scene.F.data();
  guidance.points1 = scene.xy1.data();
  guidance.points2 = scene.xy2.data();
  guidance.max_distance = 4.0;
  for (const bool cross_check : {true, false}) {
    sift.cross_check = cross_check;
    const FeatureMatches plain = CascadeMatchPair(h.a, h.b, sift, options, &scratch);
    const FeatureMatches guided = CascadeMatchPairGuided(h.a, h.b, guidance, sift, options, &scratch);
    size_t plain_true = 0, plain_decoyed_features = 0, guided_true = 0, guided_decoyed_features = 0;
    for (const FeatureMatch& m : plain) {
      const bool right = scene.truth[m.point2D_idx1] == static_cast<int>(m.point2D_idx2);
      plain_true += right;
      plain_decoyed_features += right && scene.decoy[m.point2D_idx1] >= 0;
    }
    for (const FeatureMatch& m : guided) {
      const Keypoint& p1 = scene.image1.keypoints[m.point2D_idx1];
      const Keypoint& p2 = scene.image2.keypoints[m.point2D_idx2];
      // Every guided match lies in the band, seen from either image.
      EXPECT_TRUE(LineInSecondImage(scene.F.data(), p1.x, p1.y).Contains(p2.x, p2.y, 4.0));
      if (cross_check) {
        EXPECT_TRUE(LineInFirstImage(scene.F.data(), p2.x, p2.y).Contains(p1.x, p1.y, 4.0));
      }
      EXPECT_NE(scene.decoy[m.point2D_idx1], static_cast<int>(m.point2D_idx2));
      const bool right = scene.truth[m.point2D_idx1] == static_cast<int>(m.point2D_idx2);
      guided_true += right;
      guided_decoyed_features += right && scene.decoy[m.point2D_idx1] >= 0;
    }
    // A third of the features (300) have a decoy: the ratio test drops
    // nearly all of them exhaustively, the band brings most of them back.
    EXPECT_LT(plain_decoyed_features, 60u) << "cross_check " << cross_check;
    EXPECT_GT(guided_decoyed_features, 200u) << "cross_check " << cross_check;
    EXPECT_GT(guided_true, plain_true + 150) << "cross_check " << cross_check;
    EXPECT_GE(guided_true, guided.size() * 99 / 100);
  }
}

TEST(GuidedCascade, RejectsMissingGuidance) {
  const GuidedScene scene = MakeGuidedScene(50, 13);
  const CasHashOptions options = CascadeOptions();
  const HashedScene h = Hash(scene, options);
  CascadeScratch scratch;
  EpipolarGuidance guidance;
  guidance.F = scene.F.data();
  guidance.points1 = scene.xy1.data();
  EXPECT_THROW(CascadeMatchPairGuided(h.a, h.b, guidance, SiftMatchingOptions(), options, &scratch),
               std::invalid_argument);
}

TEST(GuidedCascade, CpuMatcherMatchesPairsGuided) {
  const GuidedScene scene = MakeGuidedScene(600, 14);
  const CasHashOptions options = CascadeOptions();
  const SiftMatchingOptions sift;
  const MeanDescriptor mean = ComputeMeanDescriptor({&scene.image1.descriptors, &scene.image2.descriptors});
  auto matcher = CreateCpuFeatureMatcher(sift, options, mean);
  ASSERT_TRUE(matcher->traits().epipolar_guidance);
  matcher->AddImage(MatcherImage{1, std::make_shared<const Keypoints>(scene.image1.keypoints),
                                 std::make_shared<const FeatureDescriptors>(scene.image1.descriptors)});
  matcher->AddImage(MatcherImage{2, std::make_shared<const Keypoints>(scene.image2.keypoints),
                                 std::make_shared<const FeatureDescriptors>(scene.image2.descriptors)});
  const std::vector<EpipolarGuide> guides = {EpipolarGuide{scene.F, 4.0}};
  const std::vector<FeatureMatches> got = matcher->Match({{1, 2}}, guides);
  const HashedScene h = Hash(scene, options);
  CascadeScratch scratch;
  EpipolarGuidance guidance{scene.F.data(), scene.xy1.data(), scene.xy2.data(), 4.0};
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0], CascadeMatchPairGuided(h.a, h.b, guidance, sift, options, &scratch));
  // Too few positions for the image's features, or none.
  const Keypoints few(scene.image2.keypoints.begin(), scene.image2.keypoints.begin() + 5);
  matcher->AddImage(MatcherImage{2, std::make_shared<const Keypoints>(few),
                                 std::make_shared<const FeatureDescriptors>(scene.image2.descriptors)});
  EXPECT_THROW(matcher->Match({{1, 2}}, guides), std::invalid_argument);
  matcher->AddImage(2, scene.image2.descriptors);
  EXPECT_THROW(matcher->Match({{1, 2}}, guides), std::invalid_argument);
  EXPECT_THROW(matcher->Match({{1, 2}}, {guides[0], guides[0]}), std::invalid_argument) << "one guide per pair";

  CasHashOptions brute = options;
  brute.matcher = MatcherType::kBruteForce;
  auto exact = CreateCpuFeatureMatcher(sift, brute, mean);
  EXPECT_FALSE(exact->traits().epipolar_guidance);
  exact->AddImage(1, scene.image1.descriptors);
  exact->AddImage(2, scene.image2.descriptors);
  EXPECT_THROW(exact->Match({{1, 2}}, guides), std::logic_error);
}

// Features of a few images, served as a database would.
class MemorySource : public FeatureSource {
 public:
  void Put(image_t id, const ImageFeatures& f) {
    features_[id] = f;
    features_[id].image_id = id;
  }
  ImageFeatures LoadFeatures(image_t id) override {
    ++loads;
    return features_.at(id);
  }
  const Camera& CameraOfImage(image_t) const override { return camera_; }
  int loads = 0;

 private:
  std::map<image_t, ImageFeatures> features_;
  Camera camera_;
};

struct GuidedRig {
  MemorySource memory;
  std::unique_ptr<GuidedFeatureMatcher> matcher;
};

// An image as the pipeline adds it: features shared, keypoints included.
MatcherImage WithKeypoints(image_t id, const ImageFeatures& features) {
  auto shared = std::make_shared<const ImageFeatures>(features);
  return MatcherImage{id, std::shared_ptr<const Keypoints>(shared, &shared->keypoints),
                      std::shared_ptr<const FeatureDescriptors>(shared, &shared->descriptors)};
}

// Images 1 and 2 from the scene, 3 unrelated to both; CPU cascade for both
// stages.
std::unique_ptr<GuidedRig> MakeRig(const GuidedMatchingOptions& options, const GuidedScene& scene) {
  auto rig = std::make_unique<GuidedRig>();
  rig->memory.Put(1, scene.image1);
  rig->memory.Put(2, scene.image2);
  rig->memory.Put(3, MakeUnrelatedImage(1500, 22));
  const MeanDescriptor mean = ComputeMeanDescriptor({&scene.image1.descriptors, &scene.image2.descriptors});
  const SiftMatchingOptions sift;
  const CasHashOptions cashash = CascadeOptions();
  rig->matcher = std::make_unique<GuidedFeatureMatcher>(
      CreateCpuFeatureMatcher(sift, cashash, mean), CreateCpuFeatureMatcher(sift, cashash, mean),
      CreateCpuFundamentalEstimator(TwoViewGeometryOptions(), 2), options, 32768, 0, 2);
  for (image_t id : {1u, 2u, 3u}) rig->matcher->AddImage(WithKeypoints(id, rig->memory.LoadFeatures(id)));
  return rig;
}

std::unique_ptr<GuidedRig> MakeRig(const GuidedMatchingOptions& options) {
  return MakeRig(options, MakeGuidedScene(1500, 21));
}

// The exact (brute-force) matches of the scene's pair.
FeatureMatches ExactMatches(const GuidedScene& scene) {
  CasHashOptions brute = CascadeOptions();
  brute.matcher = MatcherType::kBruteForce;
  const MeanDescriptor mean = ComputeMeanDescriptor({&scene.image1.descriptors, &scene.image2.descriptors});
  auto exact = CreateCpuFeatureMatcher(SiftMatchingOptions(), brute, mean);
  exact->AddImage(1, scene.image1.descriptors);
  exact->AddImage(2, scene.image2.descriptors);
  return exact->Match({{1, 2}})[0];
}

TEST(GuidedBandFilter, KeepsMatchesNearBothLinesInOrder) {
  // Rows F: a match must keep its row (|y2 - y1| <= d), seen from either image.
  const std::vector<float> xy1 = {10, 100, 20, 200, 30, 300};
  const std::vector<float> xy2 = {500, 100.5f, 600, 207, 700, 296.5f};
  const FeatureMatches matches = {{0, 0}, {1, 1}, {2, 2}};
  EXPECT_EQ(KeepMatchesInEpipolarBand(matches, kRowsF, xy1, xy2, 4.0), (FeatureMatches{{0, 0}, {2, 2}}));
  EXPECT_EQ(KeepMatchesInEpipolarBand(matches, kRowsF, xy1, xy2, 8.0), matches);
  EXPECT_TRUE(KeepMatchesInEpipolarBand(matches, kRowsF, xy1, xy2, 0.4).empty());
  EXPECT_THROW(KeepMatchesInEpipolarBand({{3, 0}}, kRowsF, xy1, xy2, 4.0), std::out_of_range);
}

TEST(GuidedFeatureMatcher, OverlappingPairsAreGuidedOthersGetNothing) {
  std::unique_ptr<GuidedRig> rig = MakeRig(GuidedMatchingOptions());
  const GuidedScene scene = MakeGuidedScene(1500, 21);
  const std::vector<ImagePair> pairs = {{1, 2}, {1, 3}, {3, 2}};
  const std::vector<FeatureMatches> result = rig->matcher->Match(pairs);
  ASSERT_EQ(result.size(), 3u);
  const std::vector<GuidedStage1Outcome>& outcomes = rig->matcher->last_outcomes();
  EXPECT_EQ(outcomes[0], GuidedStage1Outcome::kGuided);
  EXPECT_EQ(outcomes[1], GuidedStage1Outcome::kTooFewMatches);
  EXPECT_EQ(outcomes[2], GuidedStage1Outcome::kTooFewMatches);
  EXPECT_TRUE(result[1].empty());
  EXPECT_TRUE(result[2].empty());
  // Stage 2 gives the pair's exact matches (all features, not only the
  // top-scale fifth, indices are rows of the whole images) that lie in the
  // band: here all of them, as they are right.
  const FeatureMatches exact = ExactMatches(scene);
  EXPECT_EQ(result[0], KeepMatchesInEpipolarBand(exact, scene.F.data(), scene.xy1, scene.xy2, 16.0));
  size_t right = 0;
  for (const FeatureMatch& m : result[0]) right += scene.truth[m.point2D_idx1] == static_cast<int>(m.point2D_idx2);
  EXPECT_GT(result[0].size(), 900u);  // of 1500, 500 of them with a decoy that the ratio test rejects
  EXPECT_GE(right, result[0].size() * 99 / 100);
  const GuidedMatchingStats& stats = rig->matcher->stats();
  EXPECT_EQ(stats.pairs, 3u);
  EXPECT_EQ(stats.pairs_enough_matches, 1u);
  EXPECT_EQ(stats.pairs_guided, 1u);
  EXPECT_EQ(stats.pairs_fallback, 0u);
  EXPECT_EQ(stats.stage2_matches, result[0].size());
  EXPECT_EQ(stats.stage2_exact_matches, exact.size());
  EXPECT_GT(stats.stage1_matches, 16u);
  EXPECT_LE(stats.stage1_matches, 300u + 20u);  // the top-scale fifth of 1500 features, plus chance matches
  EXPECT_FALSE(stats.searched_in_band);
}

TEST(GuidedFeatureMatcher, ThePapersSearchInTheBandRecoversDecoyedFeatures) {
  GuidedMatchingOptions options;
  options.restrict_search_to_band = true;
  std::unique_ptr<GuidedRig> rig = MakeRig(options);
  const GuidedScene scene = MakeGuidedScene(1500, 21);
  const std::vector<FeatureMatches> result = rig->matcher->Match({{1, 2}});
  EXPECT_EQ(rig->matcher->last_outcomes()[0], GuidedStage1Outcome::kGuided);
  size_t right = 0;
  for (const FeatureMatch& m : result[0]) right += scene.truth[m.point2D_idx1] == static_cast<int>(m.point2D_idx2);
  // The decoys lie off the line, so the band search only sees the true match.
  EXPECT_GT(result[0].size(), 1100u);
  EXPECT_GE(right, result[0].size() * 99 / 100);
  EXPECT_TRUE(rig->matcher->stats().searched_in_band);
}

TEST(GuidedFeatureMatcher, RejectsRepeatedStructureOnTheEpipolarLine) {
  // A third of the features have lost their true match and have two equally
  // good copies in image 2, one of them on their epipolar line.
  const GuidedScene scene = MakeRepeatedStructureScene(1500, 23);
  auto count = [&](const FeatureMatches& matches, size_t* right, size_t* on_line) {
    *right = *on_line = 0;
    for (const FeatureMatch& m : matches) {
      *right += scene.truth[m.point2D_idx1] == static_cast<int>(m.point2D_idx2);
      *on_line += scene.decoy[m.point2D_idx1] == static_cast<int>(m.point2D_idx2);
    }
  };
  // The paper's stage 2 accepts the copy on the line: the band leaves it
  // without a rival, and F cannot reject it.
  GuidedMatchingOptions paper;
  paper.restrict_search_to_band = true;
  std::unique_ptr<GuidedRig> searched = MakeRig(paper, scene);
  const FeatureMatches band_search = searched->matcher->Match({{1, 2}})[0];
  ASSERT_EQ(searched->matcher->last_outcomes()[0], GuidedStage1Outcome::kGuided);
  size_t right = 0, on_line = 0;
  count(band_search, &right, &on_line);
  EXPECT_GT(on_line, 300u);  // of 500
  // The default keeps only exact matches, where the copy off the line is as
  // good a rival: not one wrong match, and the unambiguous features stay.
  std::unique_ptr<GuidedRig> filtered = MakeRig(GuidedMatchingOptions(), scene);
  const FeatureMatches guided = filtered->matcher->Match({{1, 2}})[0];
  ASSERT_EQ(filtered->matcher->last_outcomes()[0], GuidedStage1Outcome::kGuided);
  count(guided, &right, &on_line);
  EXPECT_EQ(on_line, 0u);
  EXPECT_EQ(right, guided.size());
  EXPECT_GT(right, 750u);  // of the 1000 features with a unique match (810 here)
}

TEST(GuidedFeatureMatcher, StrictThresholdsSkipThePair) {
  GuidedMatchingOptions options;
  options.min_num_matches = 100000;
  options.fallback_min_num_matches = 100000;
  std::unique_ptr<GuidedRig> rig = MakeRig(options);
  const std::vector<FeatureMatches> result = rig->matcher->Match({{1, 2}});
  EXPECT_EQ(rig->matcher->last_outcomes()[0], GuidedStage1Outcome::kTooFewMatches);
  EXPECT_TRUE(result[0].empty());
}

TEST(GuidedFeatureMatcher, PairsWithoutAModelGetTheirExactMatches) {
  // Too few stage-1 matches for F (min_num_matches above them), enough for
  // the fallback: the pair's exact matches, without the band.
  GuidedMatchingOptions options;
  options.min_num_matches = 100000;
  std::unique_ptr<GuidedRig> rig = MakeRig(options);
  const std::vector<FeatureMatches> result = rig->matcher->Match({{1, 2}, {1, 3}});
  EXPECT_EQ(rig->matcher->last_outcomes()[0], GuidedStage1Outcome::kNoModel);
  EXPECT_EQ(rig->matcher->last_outcomes()[1], GuidedStage1Outcome::kTooFewMatches);
  EXPECT_EQ(result[0], ExactMatches(MakeGuidedScene(1500, 21)));
  EXPECT_TRUE(result[1].empty());
  EXPECT_EQ(rig->matcher->stats().pairs_weak, 1u);
  EXPECT_EQ(rig->matcher->stats().pairs_fallback, 1u);
  options.unguided_fallback = false;
  std::unique_ptr<GuidedRig> without = MakeRig(options);
  EXPECT_TRUE(without->matcher->Match({{1, 2}})[0].empty());
  EXPECT_EQ(without->matcher->last_outcomes()[0], GuidedStage1Outcome::kTooFewMatches);
}

TEST(GuidedFeatureMatcher, UnguidedFallbackMatchesPairsThatFailTheInlierTest) {
  // With a ratio of 1 the overlapping pair fails the inlier test: its
  // stage-1 matches hold a few chance ones that no F explains.
  GuidedMatchingOptions options;
  options.min_inlier_ratio = 1.0;
  options.unguided_fallback = false;
  std::unique_ptr<GuidedRig> without = MakeRig(options);
  const std::vector<ImagePair> pairs = {{1, 2}, {1, 3}};
  const std::vector<FeatureMatches> none = without->matcher->Match(pairs);
  ASSERT_EQ(without->matcher->last_outcomes()[0], GuidedStage1Outcome::kFewInliers);
  EXPECT_TRUE(none[0].empty());
  EXPECT_EQ(without->matcher->stats().pairs_fallback, 0u);

  options.unguided_fallback = true;
  std::unique_ptr<GuidedRig> with = MakeRig(options);
  const std::vector<FeatureMatches> result = with->matcher->Match(pairs);
  EXPECT_EQ(with->matcher->last_outcomes()[0], GuidedStage1Outcome::kFewInliers);
  EXPECT_EQ(with->matcher->last_outcomes()[1], GuidedStage1Outcome::kTooFewMatches);
  EXPECT_TRUE(result[1].empty());  // too few stage-1 matches: still nothing
  // The failed pair gets exactly the exact matches of all features.
  const FeatureMatches expected = ExactMatches(MakeGuidedScene(1500, 21));
  ASSERT_GT(expected.size(), 500u);
  EXPECT_EQ(result[0], expected);
  const GuidedMatchingStats& stats = with->matcher->stats();
  EXPECT_EQ(stats.pairs_guided, 0u);
  EXPECT_EQ(stats.pairs_fallback, 1u);
  EXPECT_EQ(stats.pairs_weak, 0u);
  EXPECT_EQ(stats.fallback_matches, result[0].size());
  EXPECT_EQ(stats.stage2_matches, 0u);
}

TEST(GuidedFeatureMatcher, NeedsKeypointsAndTheRightBackend) {
  std::unique_ptr<GuidedRig> rig = MakeRig(GuidedMatchingOptions());
  // Its traits ask for keypoints; an image added without them is refused.
  EXPECT_TRUE(rig->matcher->traits().uses_keypoints);
  EXPECT_THROW(rig->matcher->AddImage(4, MakeUnrelatedImage(10, 1).descriptors), std::logic_error);
  EXPECT_THROW(rig->matcher->Match({{1, 4}}), std::out_of_range);
  EXPECT_THROW(rig->matcher->Match({{1, 2}}, {EpipolarGuide{}}), std::logic_error) << "it makes its own guides";
  CasHashOptions brute = CascadeOptions();
  brute.matcher = MatcherType::kBruteForce;
  const MeanDescriptor mean{};
  // Brute force matches exactly, but cannot search within the band.
  GuidedMatchingOptions paper;
  paper.restrict_search_to_band = true;
  EXPECT_THROW(GuidedFeatureMatcher(CreateCpuFeatureMatcher(SiftMatchingOptions(), brute, mean),
                                    CreateCpuFeatureMatcher(SiftMatchingOptions(), CascadeOptions(), mean),
                                    CreateCpuFundamentalEstimator(TwoViewGeometryOptions(), 1), paper, 32768, 0,
                                    1),
               std::invalid_argument);
  EXPECT_NO_THROW(GuidedFeatureMatcher(CreateCpuFeatureMatcher(SiftMatchingOptions(), brute, mean),
                                       CreateCpuFeatureMatcher(SiftMatchingOptions(), CascadeOptions(), mean),
                                       CreateCpuFundamentalEstimator(TwoViewGeometryOptions(), 1),
                                       GuidedMatchingOptions(), 32768, 0, 1));
}

}  // namespace
}  // namespace cashash
