// The CPU FeatureMatcher: both matcher types, determinism across thread
// counts, truncation, error handling; and the option helpers.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "cashash/matching/brute_force_matcher.h"
#include "cashash/matching/cascade_matcher.h"
#include "cashash/matchers/exact_matcher.h"
#include "cashash/matching/matching_options.h"
#include "cashash/base/parallel_for.h"
#include "cascade_options.h"
#include "synthetic_sift.h"

namespace cashash {
namespace {

using testing_support::CascadeOptions;
using testing_support::RandomSift;

// num_images views of one scene: each image sees a random subset of `scene`
// points with a little descriptor noise, plus its own clutter.
std::vector<FeatureDescriptors> MakeImages(int num_images, size_t scene_size, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<std::vector<uint8_t>> scene;
  for (size_t i = 0; i < scene_size; ++i) scene.push_back(RandomSift(&rng));
  std::uniform_int_distribution<int> noise(-10, 10);
  std::bernoulli_distribution visible(0.6);
  std::vector<FeatureDescriptors> images(num_images);
  for (auto& image : images) {
    std::vector<std::vector<uint8_t>> rows;
    for (const auto& point : scene) {
      if (!visible(rng)) continue;
      std::vector<uint8_t> row = point;
      for (uint8_t& x : row) x = static_cast<uint8_t>(std::clamp(int(x) + noise(rng), 0, 255));
      rows.push_back(row);
    }
    for (size_t i = 0; i < scene_size / 4; ++i) rows.push_back(RandomSift(&rng));
    std::shuffle(rows.begin(), rows.end(), rng);
    for (const auto& r : rows) image.data.insert(image.data.end(), r.begin(), r.end());
  }
  return images;
}

std::vector<ImagePair> AllPairs(int num_images) {
  std::vector<ImagePair> pairs;
  for (int a = 0; a < num_images; ++a) {
    for (int b = 0; b < num_images; ++b) {
      if (a != b) pairs.push_back({image_t(a + 1), image_t(b + 1)});  // both orders
    }
  }
  return pairs;
}

std::vector<FeatureMatches> RunMatcher(const std::vector<FeatureDescriptors>& images,
                                       SiftMatchingOptions s, const CasHashOptions& o,
                                       int num_threads) {
  s.num_threads = num_threads;
  std::vector<const FeatureDescriptors*> pointers;
  for (const auto& image : images) pointers.push_back(&image);
  auto matcher = CreateCpuFeatureMatcher(s, o, ComputeMeanDescriptor(pointers));
  for (size_t i = 0; i < images.size(); ++i) matcher->AddImage(image_t(i + 1), images[i]);
  return matcher->Match(AllPairs(int(images.size())));
}

class CpuMatcherTypes : public ::testing::TestWithParam<MatcherType> {};

TEST_P(CpuMatcherTypes, DeterministicAcrossThreadCounts) {
  const std::vector<FeatureDescriptors> images = MakeImages(5, 800, 1);
  CasHashOptions o = CascadeOptions();
  o.matcher = GetParam();
  const SiftMatchingOptions s;
  const std::vector<FeatureMatches> reference = RunMatcher(images, s, o, 1);
  size_t total = 0;
  for (const auto& m : reference) total += m.size();
  EXPECT_GT(total, 20u * 200u);
  for (const int threads : {2, 3, 8, -1}) {
    EXPECT_EQ(RunMatcher(images, s, o, threads), reference) << threads << " threads";
  }
}

TEST_P(CpuMatcherTypes, SameAsTheDirectMatchers) {
  const std::vector<FeatureDescriptors> images = MakeImages(3, 500, 2);
  CasHashOptions o = CascadeOptions();
  o.matcher = GetParam();
  const SiftMatchingOptions s;
  const std::vector<FeatureMatches> results = RunMatcher(images, s, o, 2);
  const std::vector<ImagePair> pairs = AllPairs(3);
  const MeanDescriptor mean = ComputeMeanDescriptor({&images[0], &images[1], &images[2]});
  const CascadeProjections p = GenerateCascadeProjections(o);
  for (size_t i = 0; i < pairs.size(); ++i) {
    const FeatureDescriptors& a = images[pairs[i].first - 1];
    const FeatureDescriptors& b = images[pairs[i].second - 1];
    FeatureMatches expected;
    if (o.matcher == MatcherType::kCascade) {
      CascadeScratch scratch;
      expected = CascadeMatchPair(BuildCascadeImage(a, a.rows(), p, mean),
                                  BuildCascadeImage(b, b.rows(), p, mean), s, o, &scratch);
    } else {
      expected = BruteForceMatchPair(WidenDescriptors(a, a.rows()), WidenDescriptors(b, b.rows()), s);
    }
    EXPECT_EQ(results[i], expected) << "pair " << i;
  }
}

TEST_P(CpuMatcherTypes, TruncatesToMaxNumMatches) {
  const std::vector<FeatureDescriptors> images = MakeImages(2, 600, 3);
  CasHashOptions o = CascadeOptions();
  o.matcher = GetParam();
  SiftMatchingOptions s;
  s.max_num_matches = 150;
  std::vector<FeatureDescriptors> truncated = images;
  for (auto& image : truncated) image.data.resize(150 * kDescriptorDim);
  const std::vector<FeatureMatches> full = RunMatcher(images, s, o, 1);
  // RunMatcher computes the mean from the images it is given, so the cascade
  // hashes differ between the two runs; the exact brute force must agree.
  const std::vector<FeatureMatches> cut = RunMatcher(truncated, s, o, 1);
  for (const auto& matches : full) {
    EXPECT_FALSE(matches.empty());
    for (const FeatureMatch& m : matches) {
      EXPECT_LT(m.point2D_idx1, 150u);
      EXPECT_LT(m.point2D_idx2, 150u);
    }
  }
  if (o.matcher == MatcherType::kBruteForce) {
    EXPECT_EQ(full, cut);
  }
}

TEST_P(CpuMatcherTypes, EmptyAndSingleFeatureImages) {
  std::mt19937 rng(4);
  FeatureDescriptors empty, one, many;
  one.data = RandomSift(&rng);
  for (int i = 0; i < 30; ++i) {
    const auto r = RandomSift(&rng);
    many.data.insert(many.data.end(), r.begin(), r.end());
  }
  many.data.insert(many.data.end(), one.data.begin(), one.data.end());  // copy at row 30
  CasHashOptions o = CascadeOptions();
  o.matcher = GetParam();
  auto matcher = CreateCpuFeatureMatcher(SiftMatchingOptions(), o, ComputeMeanDescriptor({&many}));
  matcher->AddImage(1, empty);
  matcher->AddImage(2, one);
  matcher->AddImage(3, many);
  const auto results = matcher->Match({{1, 3}, {3, 1}, {1, 1}, {2, 3}, {3, 2}, {1, 2}});
  ASSERT_EQ(results.size(), 6u);
  for (int i : {0, 1, 2, 5}) EXPECT_TRUE(results[i].empty());
  EXPECT_EQ(results[3], (FeatureMatches{{0, 30}}));
  EXPECT_EQ(results[4], (FeatureMatches{{30, 0}}));
  EXPECT_TRUE(matcher->Match({}).empty());
}

TEST_P(CpuMatcherTypes, ReplaceRemoveAndUnknownImages) {
  const std::vector<FeatureDescriptors> images = MakeImages(2, 300, 5);
  CasHashOptions o = CascadeOptions();
  o.matcher = GetParam();
  auto matcher = CreateCpuFeatureMatcher(SiftMatchingOptions(), o,
                                         ComputeMeanDescriptor({&images[0], &images[1]}));
  EXPECT_EQ(matcher->Name(), GetParam() == MatcherType::kCascade ? "cpu-cascade" : "cpu-bruteforce");
  matcher->AddImage(1, images[0]);
  matcher->AddImage(2, images[0]);
  const size_t self_matches = matcher->Match({{1, 2}})[0].size();
  matcher->AddImage(2, images[1]);  // replaces
  const size_t other_matches = matcher->Match({{1, 2}})[0].size();
  EXPECT_GT(self_matches, other_matches);
  EXPECT_THROW(matcher->Match({{1, 9}}), std::out_of_range);
  matcher->RemoveImage(2);
  EXPECT_THROW(matcher->Match({{1, 2}}), std::out_of_range);
}

INSTANTIATE_TEST_SUITE_P(Both, CpuMatcherTypes,
                         ::testing::Values(MatcherType::kCascade, MatcherType::kBruteForce));

TEST(CpuFeatureMatcher, RejectsInvalidOptions) {
  const MeanDescriptor mean{};
  SiftMatchingOptions bad_sift;
  bad_sift.max_ratio = 0;
  EXPECT_THROW(CreateCpuFeatureMatcher(bad_sift, CascadeOptions(), mean), std::invalid_argument);
  CasHashOptions bad_cascade = CascadeOptions();
  bad_cascade.top_k = 0;
  EXPECT_THROW(CreateCpuFeatureMatcher(SiftMatchingOptions(), bad_cascade, mean), std::invalid_argument);
}

// The values a run chooses (matcher auto, tau 0, rematch threshold -1, the
// defaults) are valid options, but a matcher built directly refuses them,
// naming the option, rather than guess: ResolveRun decides them for a run.
TEST(CpuFeatureMatcher, RefusesValuesChosenForTheRun) {
  const MeanDescriptor mean{};
  struct Case {
    const char* option;
    void (*leave_to_the_run)(CasHashOptions*);
  };
  const Case cases[] = {
      {"--CasHash.matcher auto", [](CasHashOptions* o) { o->matcher = MatcherType::kAuto; }},
      {"--CasHash.tau 0", [](CasHashOptions* o) { o->tau = kTauChosen; }},
      {"--CasHash.exact_rematch_min_matches -1",
       [](CasHashOptions* o) { o->exact_rematch_min_matches = kRematchMinMatchesChosen; }},
  };
  for (const Case& c : cases) {
    CasHashOptions options = CascadeOptions();
    c.leave_to_the_run(&options);
    EXPECT_EQ(options.Check(), "") << c.option;
    EXPECT_NE(options.CheckDecided().find(c.option), std::string::npos) << options.CheckDecided();
    try {
      CreateCpuFeatureMatcher(SiftMatchingOptions(), options, mean);
      ADD_FAILURE() << "built a matcher with " << c.option;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(c.option), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("ResolveRun"), std::string::npos) << e.what();
    }
  }
  EXPECT_EQ(CascadeOptions().CheckDecided(), "");
  EXPECT_NE(CasHashOptions().CheckDecided(), "");
}

TEST(MatchingOptions, Check) {
  EXPECT_EQ(SiftMatchingOptions().Check(), "");
  EXPECT_EQ(CasHashOptions().Check(), "");
  SiftMatchingOptions s;
  s.num_threads = 0;
  EXPECT_NE(s.Check().find("num_threads"), std::string::npos);
  s = SiftMatchingOptions();
  s.max_distance = -1;
  EXPECT_NE(s.Check().find("max_distance"), std::string::npos);
  s = SiftMatchingOptions();
  s.max_num_matches = 0;
  EXPECT_NE(s.Check().find("max_num_matches"), std::string::npos);
  CasHashOptions o;
  o.tau = 129;
  EXPECT_NE(o.Check().find("tau"), std::string::npos);
  o = CasHashOptions();
  o.bits_per_table = -1;
  EXPECT_NE(o.Check().find("bits_per_table"), std::string::npos);
  o = CasHashOptions();
  o.num_tables = -1;
  EXPECT_NE(o.Check().find("num_tables"), std::string::npos);
  // 0 = chosen from the feature counts (the defaults).
  o = CasHashOptions();
  EXPECT_EQ(o.num_tables, 0);
  EXPECT_EQ(o.bits_per_table, 0);
  EXPECT_EQ(o.Check(), "");
}

TEST(MatchingOptions, MatcherTypeNames) {
  for (MatcherType type : {MatcherType::kCascade, MatcherType::kBruteForce, MatcherType::kAuto}) {
    MatcherType parsed;
    ASSERT_TRUE(MatcherTypeFromString(MatcherTypeToString(type), &parsed));
    EXPECT_EQ(parsed, type);
  }
  EXPECT_EQ(MatcherTypeToString(MatcherType::kCascade), "cascade");
  EXPECT_EQ(MatcherTypeToString(MatcherType::kBruteForce), "bruteforce");
  EXPECT_EQ(MatcherTypeToString(MatcherType::kAuto), "auto");
  // One set of defaults: auto, chosen for the run, for the library as for
  // runs (CommandOptions.CasHashOptionsKeepOneSetOfDefaults).
  EXPECT_EQ(CasHashOptions().matcher, MatcherType::kAuto);
  MatcherType parsed = MatcherType::kCascade;
  EXPECT_FALSE(MatcherTypeFromString("exhaustive", &parsed));
  EXPECT_EQ(parsed, MatcherType::kCascade);
}

TEST(ParallelFor, VisitsEveryIndexOnceAndRethrows) {
  for (const int threads : {1, 2, 7, -1}) {
    std::vector<int> visits(1000, 0);
    ParallelFor(visits.size(), threads, [&](size_t i) { ++visits[i]; });
    EXPECT_EQ(std::count(visits.begin(), visits.end(), 1), 1000) << threads;
  }
  EXPECT_THROW(ParallelFor(100, 4, [](size_t i) { if (i == 37) throw std::runtime_error("x"); }),
               std::runtime_error);
  ParallelFor(0, 4, [](size_t) { FAIL(); });
}

}  // namespace
}  // namespace cashash
