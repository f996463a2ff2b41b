#include "colmap_bridge/api/command_options.h"
#include "cashash/matching/matcher_choice.h"
#include "colmap_bridge/api/matching_api.h"
#include "colmap_bridge/api/run_resolution.h"
#include "cashash/matching/table_shape.h"

#include <gtest/gtest.h>

namespace cashash {
namespace colmap {
namespace {

// The run of `options` over images of `rows` features each (a pair list);
// what it chose is appended to *notes when given.
ResolvedRun Resolve(const MatcherCommandOptions& options, const std::vector<size_t>& rows,
                    std::vector<std::string>* notes = nullptr) {
  RunFacts facts;
  facts.rows_per_image = rows;
  facts.exhaustive = false;
  ResolvedRun run = ResolveRun(options, facts);
  if (notes != nullptr) notes->insert(notes->end(), run.notes.begin(), run.notes.end());
  return run;
}

// The same run matched on device 0: the GPU's rules, on whichever machine
// the test runs.
ResolvedRun ResolveOnGpu(const MatcherCommandOptions& options, const std::vector<size_t>& rows,
                         std::vector<std::string>* notes = nullptr) {
  RunFacts facts;
  facts.rows_per_image = rows;
  facts.exhaustive = false;
  facts.gpu_indices = {0};
  ResolvedRun run = ResolveRun(options, facts);
  if (notes != nullptr) notes->insert(notes->end(), run.notes.begin(), run.notes.end());
  return run;
}

ParseOutcome Parse(std::vector<const char*> args, MatcherCommandOptions* options) {
  args.insert(args.begin(), "exhaustive_matcher");
  return ParseMatcherCommandOptions("exhaustive_matcher", static_cast<int>(args.size()), args.data(), options);
}

TEST(CommandOptions, DefaultsAreColmaps) {
  MatcherCommandOptions o;
  ASSERT_EQ(Parse({"--database_path", "db.db"}, &o), ParseOutcome::kRun);
  EXPECT_EQ(o.database_path, "db.db");
  EXPECT_DOUBLE_EQ(o.sift.max_ratio, 0.8);
  EXPECT_DOUBLE_EQ(o.sift.max_distance, 0.7);
  EXPECT_TRUE(o.sift.cross_check);
  EXPECT_EQ(o.sift.max_num_matches, 32768);
  EXPECT_EQ(o.two_view.min_num_inliers, 15);
  EXPECT_DOUBLE_EQ(o.two_view.max_error, 4.0);
  EXPECT_DOUBLE_EQ(o.two_view.confidence, 0.999);
  EXPECT_EQ(o.two_view.max_num_trials, 10000);
  EXPECT_DOUBLE_EQ(o.two_view.min_inlier_ratio, 0.25);
  EXPECT_EQ(o.block_size, 0);  // chosen: from the memory caps, at most 50
  EXPECT_TRUE(o.use_gpu);
  EXPECT_EQ(CheckMatcherCommandOptions(o), "");
}

TEST(CommandOptions, Colmap38Names) {
  MatcherCommandOptions o;
  ASSERT_EQ(Parse({"--database_path", "x", "--SiftMatching.use_gpu", "0", "--SiftMatching.max_ratio", "0.7",
                   "--SiftMatching.max_error", "2", "--SiftMatching.min_num_inliers", "30",
                   "--SiftMatching.num_threads", "3", "--SiftMatching.cross_check", "0",
                   "--ExhaustiveMatching.block_size", "10"},
                  &o),
            ParseOutcome::kRun);
  EXPECT_FALSE(o.use_gpu);
  EXPECT_DOUBLE_EQ(o.sift.max_ratio, 0.7);
  EXPECT_DOUBLE_EQ(o.two_view.max_error, 2.0);
  EXPECT_EQ(o.two_view.min_num_inliers, 30);
  EXPECT_EQ(o.sift.num_threads, 3);
  EXPECT_FALSE(o.sift.cross_check);
  EXPECT_EQ(o.block_size, 10);
}

TEST(CommandOptions, Colmap4Names) {
  MatcherCommandOptions o;
  ASSERT_EQ(Parse({"--database_path", "x", "--FeatureMatching.use_gpu", "false", "--FeatureMatching.gpu_index",
                   "1", "--TwoViewGeometry.max_error", "3", "--TwoViewGeometry.confidence", "0.99",
                   "--FeatureMatching.max_num_matches", "1000", "--CasHash.matcher", "bruteforce",
                   "--random_seed", "7"},
                  &o),
            ParseOutcome::kRun);
  EXPECT_FALSE(o.use_gpu);
  EXPECT_EQ(o.gpu_index, "1");
  EXPECT_DOUBLE_EQ(o.two_view.max_error, 3.0);
  EXPECT_DOUBLE_EQ(o.two_view.confidence, 0.99);
  EXPECT_EQ(o.sift.max_num_matches, 1000);
  EXPECT_EQ(o.cashash.matcher, MatcherType::kBruteForce);
  EXPECT_EQ(o.cashash.random_seed, 7u);
  EXPECT_EQ(o.two_view.random_seed, 7u);
}

TEST(CommandOptions, BadInputIsAnError) {
  MatcherCommandOptions o;
  EXPECT_EQ(Parse({"--database_path", "x", "--SiftMatching.max_ratio", "abc"}, &o), ParseOutcome::kError);
  MatcherCommandOptions o2;
  EXPECT_EQ(Parse({"--no_such_option", "1"}, &o2), ParseOutcome::kError);
  MatcherCommandOptions o3;
  EXPECT_EQ(Parse({"--CasHash.matcher", "kdtree"}, &o3), ParseOutcome::kError);
  MatcherCommandOptions o4;
  ASSERT_EQ(Parse({"--ExhaustiveMatching.block_size", "1", "--database_path", "x"}, &o4), ParseOutcome::kRun);
  EXPECT_NE(CheckMatcherCommandOptions(o4).find("ExhaustiveMatching.block_size"), std::string::npos);
  MatcherCommandOptions o5;
  ASSERT_EQ(Parse({}, &o5), ParseOutcome::kRun);
  EXPECT_NE(CheckMatcherCommandOptions(o5).find("--database_path"), std::string::npos);
}

TEST(CommandOptions, MatcherAndTablesDefaultToAutoAndExplicitValuesWin) {
  MatcherCommandOptions defaults;
  ASSERT_EQ(Parse({"--database_path", "x"}, &defaults), ParseOutcome::kRun);
  EXPECT_EQ(defaults.cashash.matcher, MatcherType::kAuto);
  EXPECT_EQ(defaults.cashash.num_tables, 0);
  EXPECT_EQ(defaults.cashash.bits_per_table, 0);
  EXPECT_EQ(CheckMatcherCommandOptions(defaults), "");
  // Given on the command line, the tables are kept for any image size.
  MatcherCommandOptions set;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.num_tables", "8", "--CasHash.bits_per_table", "7",
                   "--CasHash.matcher", "cascade"},
                  &set),
            ParseOutcome::kRun);
  EXPECT_EQ(set.cashash.matcher, MatcherType::kCascade);
  const MatcherCommandOptions run = Resolve(set, {32768, 32768, 32768}).options;
  EXPECT_EQ(run.cashash.num_tables, 8);
  EXPECT_EQ(run.cashash.bits_per_table, 7);
  // Left at 0, they follow the images: at 32,768 features on the CPU
  // 22 x 13 for recall (buckets of about 4 features, kCpuFineBucketFeatures),
  // and on a GPU 3 x 10 while the exact rematch decides (the default), since
  // the cascade then only screens the pairs (TableShapeGoal).
  const MatcherCommandOptions chosen = ResolveOnGpu(defaults, {32768, 32768, 32768}).options;
  EXPECT_EQ(chosen.cashash.num_tables, 3);
  EXPECT_EQ(chosen.cashash.bits_per_table, 10);
  MatcherCommandOptions kept;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.exact_rematch_min_matches", "0"}, &kept), ParseOutcome::kRun);
  const MatcherCommandOptions for_recall = Resolve(kept, {32768, 32768, 32768}).options;
  EXPECT_EQ(for_recall.cashash.num_tables, 22);
  EXPECT_EQ(for_recall.cashash.bits_per_table, 13);
  MatcherCommandOptions guided = defaults;
  guided.guided.enabled = true;
  EXPECT_EQ(Resolve(guided, {8192, 8192}).options.cashash.bits_per_table, 7);
  EXPECT_EQ(ResolveOnGpu(defaults, {8192, 8192}).options.cashash.bits_per_table, 9);  // 3 x 9
  MatcherCommandOptions auto_named;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.matcher", "auto"}, &auto_named), ParseOutcome::kRun);
  EXPECT_EQ(auto_named.cashash.matcher, MatcherType::kAuto);
}

// CasHashOptions has one set of defaults: the runs' options take the
// struct's own, field by field, so that the library, the command line and
// Python cannot drift apart. A field added to CasHashOptions belongs here.
TEST(CommandOptions, CasHashOptionsKeepOneSetOfDefaults) {
  const CasHashOptions library;
  const CasHashOptions run = MatcherCommandOptions().cashash;
  EXPECT_EQ(library.matcher, run.matcher);
  EXPECT_EQ(library.num_tables, run.num_tables);
  EXPECT_EQ(library.bits_per_table, run.bits_per_table);
  EXPECT_EQ(library.tau, run.tau);
  EXPECT_EQ(library.top_k, run.top_k);
  EXPECT_EQ(library.random_seed, run.random_seed);
  EXPECT_EQ(library.exact_rematch_min_matches, run.exact_rematch_min_matches);
  EXPECT_EQ(library.exact_rematch_max_matches, run.exact_rematch_max_matches);
  // They are the values chosen for the run.
  EXPECT_EQ(library.matcher, MatcherType::kAuto);
  EXPECT_EQ(library.tau, kTauChosen);
  EXPECT_EQ(library.exact_rematch_min_matches, kRematchMinMatchesChosen);
  EXPECT_EQ(library.Check(), "");
}

// ResolveRun decides every value chosen for the run, on either device and
// for every matcher, so that the matcher factories accept what it gives them.
TEST(CommandOptions, AResolvedRunLeavesNothingToChoose) {
  MatcherCommandOptions brute_force;
  brute_force.cashash.matcher = MatcherType::kBruteForce;
  MatcherCommandOptions guided;
  guided.guided.enabled = true;
  MatcherCommandOptions no_rematch;
  no_rematch.cashash.exact_rematch_min_matches = 0;
  for (const MatcherCommandOptions& options : {MatcherCommandOptions(), brute_force, guided, no_rematch}) {
    for (const size_t features : {size_t{500}, size_t{8192}, size_t{32768}}) {
      EXPECT_EQ(Resolve(options, {features, features}).options.cashash.CheckDecided(), "") << features;
      EXPECT_EQ(ResolveOnGpu(options, {features, features}).options.cashash.CheckDecided(), "") << features;
    }
  }
}

TEST(CommandOptions, TauIsChosenForScreeningOnlyWhileTheExactRematchDecides) {
  MatcherCommandOptions defaults;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.matcher", "cascade"}, &defaults), ParseOutcome::kRun);
  EXPECT_EQ(defaults.cashash.tau, 0);
  EXPECT_EQ(CheckMatcherCommandOptions(defaults), "");
  std::vector<std::string> said;
  // The default run on a GPU: the rematch decides every pair that may verify.
  EXPECT_EQ(ResolveOnGpu(defaults, {8192, 8192}, &said).options.cashash.tau, kCascadeTauForScreening);
  ASSERT_FALSE(said.empty());
  EXPECT_NE(said.back().find("tau 32 (chosen: the exact rematch"), std::string::npos) << said.back();
  // Without the rematch the cascade's matches are kept: tau for precision.
  MatcherCommandOptions kept;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.exact_rematch_min_matches", "0"}, &kept), ParseOutcome::kRun);
  EXPECT_EQ(Resolve(kept, {8192, 8192}).options.cashash.tau, kCascadeTauForPrecision);
  // Guided matching fits F to stage 1's cascade matches.
  const char* guided_argv[] = {"guided_matcher", "--database_path", "x"};
  MatcherCommandOptions guided;
  ASSERT_EQ(ParseMatcherCommandOptions("guided_matcher", 3, guided_argv, &guided), ParseOutcome::kRun);
  EXPECT_EQ(Resolve(guided, {8192, 8192}).options.cashash.tau, kCascadeTauForPrecision);
  // Given on the command line, tau is kept whatever the rematch.
  MatcherCommandOptions set;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.tau", "40"}, &set), ParseOutcome::kRun);
  said.clear();
  EXPECT_EQ(Resolve(set, {8192, 8192}, &said).options.cashash.tau, 40);
  ASSERT_FALSE(said.empty());
  EXPECT_EQ(said.back().find("chosen: the exact"), std::string::npos) << said.back();
}

TEST(CommandOptions, TheRematchThresholdFollowsTheBucketScreeningTablesUnlessGiven) {
  const auto threshold = [](const MatcherCommandOptions& options, size_t features) {
    return ResolveOnGpu(options, {features, features}).options.cashash.exact_rematch_min_matches;
  };
  MatcherCommandOptions defaults;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.matcher", "cascade"}, &defaults), ParseOutcome::kRun);
  EXPECT_EQ(defaults.cashash.exact_rematch_min_matches, kRematchMinMatchesChosen);
  EXPECT_EQ(defaults.cashash.exact_rematch_max_matches, 0);
  // Three screening tables from 4,096 features find fewer of a pair's true
  // matches: the threshold measured for them. Below, the 8 x 8 screen keeps 12.
  EXPECT_EQ(threshold(defaults, 4096), kBucketScreeningRematchMinMatches);
  EXPECT_EQ(threshold(defaults, 8192), kBucketScreeningRematchMinMatches);
  EXPECT_EQ(threshold(defaults, 16384), kBucketScreeningRematchMinMatches);
  EXPECT_EQ(threshold(defaults, 4095), kDefaultRematchMinMatches);
  std::vector<std::string> said;
  ResolveOnGpu(defaults, {8192, 8192}, &said);
  ASSERT_FALSE(said.empty());
  EXPECT_NE(said.back().find("exact rematch from 8 cascade matches (chosen for these tables)"), std::string::npos)
      << said.back();
  // Typed on the command line, even 12 is kept.
  MatcherCommandOptions typed;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.exact_rematch_min_matches", "12"}, &typed), ParseOutcome::kRun);
  EXPECT_EQ(typed.cashash.exact_rematch_min_matches, 12);
  EXPECT_EQ(threshold(typed, 8192), 12);
  // Set through the library (the Python module's options), any value is
  // kept, 12 included.
  MatcherCommandOptions api;
  api.cashash.matcher = MatcherType::kCascade;
  api.cashash.exact_rematch_min_matches = 10;
  EXPECT_EQ(threshold(api, 8192), 10);
  api.cashash.exact_rematch_min_matches = 12;
  EXPECT_EQ(threshold(api, 8192), 12);
  // Tables or bits given: the shape is the user's, so is the threshold.
  MatcherCommandOptions tables;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.num_tables", "6"}, &tables), ParseOutcome::kRun);
  EXPECT_EQ(threshold(tables, 8192), kDefaultRematchMinMatches);
  MatcherCommandOptions bits;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.bits_per_table", "9"}, &bits), ParseOutcome::kRun);
  EXPECT_EQ(threshold(bits, 8192), kDefaultRematchMinMatches);
  // Guided matching keeps its cascade's matches for stage 1: no rematch.
  MatcherCommandOptions guided = defaults;
  guided.guided.enabled = true;
  EXPECT_EQ(threshold(guided, 8192), kDefaultRematchMinMatches);
}

// The bucket screen leaves the matching thread room: a single GPU's exact
// rematch stays there instead of going to the verification threads.
TEST(CommandOptions, TheRematchRunsOnTheMatchingThreadWithTheBucketScreen) {
  const auto on_matching_thread = [](const MatcherCommandOptions& options, size_t features) {
    return ResolveOnGpu(options, {features, features}).rematch.where == RematchPlace::kMatchingThread;
  };
  MatcherCommandOptions defaults;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.matcher", "cascade"}, &defaults), ParseOutcome::kRun);
  EXPECT_TRUE(on_matching_thread(defaults, 8192));
  EXPECT_TRUE(on_matching_thread(defaults, 16384));
  EXPECT_TRUE(on_matching_thread(defaults, 4096));
  EXPECT_FALSE(on_matching_thread(defaults, 4095));  // 8 x 8 tables: deferred
  // The bucket screen with a threshold of the user's: the screen decides.
  MatcherCommandOptions typed;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.exact_rematch_min_matches", "12"}, &typed), ParseOutcome::kRun);
  EXPECT_TRUE(on_matching_thread(typed, 8192));
  // Tables given, or guided matching: not the bucket screen, deferred.
  MatcherCommandOptions tables;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.num_tables", "6"}, &tables), ParseOutcome::kRun);
  EXPECT_FALSE(on_matching_thread(tables, 8192));
  MatcherCommandOptions guided = defaults;
  guided.guided.enabled = true;
  EXPECT_FALSE(on_matching_thread(guided, 8192));
}

// auto on the CPU (matcher_choice.h): the cascade's own matches, tables and
// tau for them, and the exact rematch of the pairs in the window only; a
// threshold or window set through the library or typed is kept.
TEST(CommandOptions, AutoOnTheCpuKeepsTheCascadesMatchesAndRematchesTheWindow) {
  MatcherCommandOptions cpu;
  ASSERT_EQ(Parse({"--database_path", "x", "--FeatureMatching.use_gpu", "0"}, &cpu), ParseOutcome::kRun);
  std::vector<std::string> said;
  const MatcherCommandOptions run = Resolve(cpu, {8192, 8192}, &said).options;
  EXPECT_EQ(run.cashash.matcher, MatcherType::kCascade);
  EXPECT_EQ(run.cashash.exact_rematch_min_matches, kCpuRematchWindowMin);
  EXPECT_EQ(run.cashash.exact_rematch_max_matches, kCpuRematchWindowMax);
  EXPECT_EQ(run.cashash.tau, kCascadeTauForPrecision);
  EXPECT_EQ(run.cashash.num_tables, 8);
  EXPECT_EQ(run.cashash.bits_per_table, 7);
  ASSERT_FALSE(said.empty());
  EXPECT_EQ(said.front(), "Matcher: cascade, exact rematch of pairs with 12 to 63 cascade matches (CPU rule)");
  MatcherCommandOptions api = cpu;
  api.cashash.exact_rematch_min_matches = 10;
  const MatcherCommandOptions kept = Resolve(api, {8192, 8192}).options;
  EXPECT_EQ(kept.cashash.exact_rematch_min_matches, 10);
  EXPECT_EQ(kept.cashash.exact_rematch_max_matches, 0);
  MatcherCommandOptions window;
  ASSERT_EQ(Parse({"--database_path", "x", "--FeatureMatching.use_gpu", "0", "--CasHash.exact_rematch_max_matches",
                   "96"},
                  &window),
            ParseOutcome::kRun);
  EXPECT_EQ(CheckMatcherCommandOptions(window), "");
  const MatcherCommandOptions typed_window = Resolve(window, {8192, 8192}).options;
  EXPECT_EQ(typed_window.cashash.exact_rematch_min_matches, kDefaultRematchMinMatches);
  EXPECT_EQ(typed_window.cashash.exact_rematch_max_matches, 96);
  MatcherCommandOptions off;
  ASSERT_EQ(Parse({"--database_path", "x", "--FeatureMatching.use_gpu", "0", "--CasHash.exact_rematch_min_matches",
                   "0"},
                  &off),
            ParseOutcome::kRun);
  EXPECT_EQ(Resolve(off, {8192, 8192}).options.cashash.exact_rematch_min_matches, 0);
  // A window whose top is not above the threshold is refused, naming it.
  MatcherCommandOptions below;
  ASSERT_EQ(Parse({"--database_path", "x", "--CasHash.exact_rematch_max_matches", "12"}, &below), ParseOutcome::kRun);
  EXPECT_NE(CheckMatcherCommandOptions(below).find("CasHash.exact_rematch_max_matches"), std::string::npos);
}

TEST(CommandOptions, GuidedMatchingResolvesAutoToTheCascadeAndRefusesBruteForce) {
  const char* argv[] = {"guided_matcher", "--database_path", "x"};
  MatcherCommandOptions o;
  ASSERT_EQ(ParseMatcherCommandOptions("guided_matcher", 3, argv, &o), ParseOutcome::kRun);
  EXPECT_TRUE(o.guided.enabled);
  EXPECT_EQ(CheckMatcherCommandOptions(o), "");
  std::vector<std::string> said;
  const MatcherCommandOptions run = Resolve(o, {1000, 2000}, &said).options;
  EXPECT_EQ(run.cashash.matcher, MatcherType::kCascade);
  ASSERT_FALSE(said.empty());
  EXPECT_NE(said.front().find("guided"), std::string::npos);
  o.cashash.matcher = MatcherType::kBruteForce;
  EXPECT_NE(CheckMatcherCommandOptions(o).find("GuidedMatching.enabled"), std::string::npos);
}

TEST(CommandOptions, HelpListsOptions) {
  MatcherCommandOptions o;
  testing::internal::CaptureStdout();
  EXPECT_EQ(Parse({"--help"}, &o), ParseOutcome::kHelpShown);
  const std::string help = testing::internal::GetCapturedStdout();
  for (const char* name : {"--SiftMatching.max_ratio", "--FeatureMatching.use_gpu", "--TwoViewGeometry.max_error",
                           "--CasHash.tau", "--ExhaustiveMatching.block_size", "--SiftMatching.min_num_inliers"}) {
    EXPECT_NE(help.find(name), std::string::npos) << name;
  }
}

ParseOutcome ParseCommand(const char* command, std::vector<const char*> args, MatcherCommandOptions* options) {
  args.insert(args.begin(), command);
  return ParseMatcherCommandOptions(command, static_cast<int>(args.size()), args.data(), options);
}

TEST(CommandOptions, SequentialMatchingUnderColmapsNames) {
  MatcherCommandOptions o;
  ASSERT_EQ(ParseCommand("sequential_matcher",
                         {"--database_path", "x", "--SequentialMatching.overlap", "5",
                          "--SequentialMatching.quadratic_overlap", "0", "--SequentialMatching.loop_detection", "1",
                          "--SequentialMatching.loop_detection_period", "7",
                          "--SequentialMatching.loop_detection_num_images", "30",
                          "--SequentialMatching.loop_detection_min_index_distance", "20",
                          "--SequentialMatching.expand_rig_images", "false",
                          "--SequentialMatching.vocab_tree_path", "tree.bin",
                          "--SequentialMatching.loop_detection_num_checks", "128"},
                         &o),
            ParseOutcome::kRun);
  EXPECT_EQ(o.sequential.overlap, 5);
  EXPECT_FALSE(o.sequential.quadratic_overlap);
  EXPECT_TRUE(o.sequential.loop_detection);
  EXPECT_EQ(o.sequential.loop_detection_period, 7);
  EXPECT_EQ(o.sequential.loop_detection_num_images, 30);
  EXPECT_EQ(o.sequential.loop_detection_min_index_distance, 20);
  EXPECT_FALSE(o.sequential.expand_rig_images);
  EXPECT_EQ(o.sequential.vocab_tree_path, "tree.bin");
  EXPECT_EQ(CheckMatcherCommandOptions(o), "");
  o = MatcherCommandOptions();
  ASSERT_EQ(ParseCommand("sequential_matcher", {"--database_path", "x", "--SequentialMatching.overlap", "0"}, &o),
            ParseOutcome::kRun);
  EXPECT_NE(CheckMatcherCommandOptions(o).find("--SequentialMatching.overlap"), std::string::npos);
  // Another command's options are unknown options.
  EXPECT_EQ(ParseCommand("sequential_matcher", {"--database_path", "x", "--SpatialMatching.max_distance", "5"}, &o),
            ParseOutcome::kError);
  EXPECT_EQ(ParseCommand("exhaustive_matcher", {"--database_path", "x", "--SequentialMatching.overlap", "5"}, &o),
            ParseOutcome::kError);
}

TEST(CommandOptions, SpatialMatchingUnderColmapsNames) {
  MatcherCommandOptions o;
  ASSERT_EQ(ParseCommand("spatial_matcher",
                         {"--database_path", "x", "--SpatialMatching.max_num_neighbors", "20",
                          "--SpatialMatching.min_num_neighbors", "3", "--SpatialMatching.max_distance", "25.5",
                          "--SpatialMatching.ignore_z", "0", "--SpatialMatching.is_gps", "0"},
                         &o),
            ParseOutcome::kRun);
  EXPECT_EQ(o.spatial.max_num_neighbors, 20);
  EXPECT_EQ(o.spatial.min_num_neighbors, 3);
  EXPECT_DOUBLE_EQ(o.spatial.max_distance, 25.5);
  EXPECT_FALSE(o.spatial.ignore_z);
  EXPECT_FALSE(o.spatial.is_gps);
  EXPECT_EQ(CheckMatcherCommandOptions(o), "");
  o.spatial.min_num_neighbors = 21;
  EXPECT_NE(CheckMatcherCommandOptions(o).find("--SpatialMatching.min_num_neighbors"), std::string::npos);
  EXPECT_EQ(ParseCommand("spatial_matcher", {"--database_path", "x", "--SpatialMatching.max_neighbors", "5"}, &o),
            ParseOutcome::kError);
}

}  // namespace
}  // namespace colmap
}  // namespace cashash
