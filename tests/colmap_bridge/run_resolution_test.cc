// ResolveRun: the user's options and the facts of the database and the
// machine in, the resolved run out, as a table; and the same inputs given
// on the command line and set as Python sets them resolve alike.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "cashash/matching/table_shape.h"
#include "colmap_bridge/api/command_options.h"
#include "colmap_bridge/api/run_devices.h"
#include "colmap_bridge/api/run_resolution.h"

namespace cashash {
namespace colmap {
namespace {

constexpr size_t kMiB = size_t{1} << 20;
constexpr size_t kGiB = size_t{1} << 30;

RunFacts Facts(size_t images, size_t rows, bool exhaustive, size_t physical = 16 * kGiB, int gpu_index = -1,
               size_t gpu_free = 0) {
  RunFacts facts;
  facts.rows_per_image.assign(images, rows);
  facts.exhaustive = exhaustive;
  facts.physical_memory_bytes = physical;
  if (gpu_index >= 0) facts.gpu_indices = {gpu_index};
  facts.gpu_free_bytes = gpu_free;
  return facts;
}

// What a resolved run decides, as one line, to compare runs whole.
std::string Decisions(const ResolvedRun& run) {
  const CasHashOptions& c = run.options.cashash;
  std::ostringstream out;
  out << MatcherTypeToString(c.matcher) << " " << c.num_tables << "x" << c.bits_per_table << " tau " << c.tau
      << " rematch " << c.exact_rematch_min_matches << " to " << c.exact_rematch_max_matches
      << " on the " << RematchPlaceName(run.rematch.where)
      << " block " << run.options.block_size << " groups " << run.schedule.blocks_per_group << " keep "
      << run.schedule.matcher_keep_bytes << " host " << run.max_host_bytes << " gpu " << run.max_gpu_bytes
      << " budget " << run.gpu_memory_budget_bytes << " device " << run.gpu_index;
  return out.str();
}

// The options as the command line parses `args` (after the command name).
MatcherCommandOptions FromCommandLine(const std::vector<std::string>& args, const std::string& command) {
  std::vector<const char*> argv = {command.c_str(), "--database_path", "x.db"};
  for (const std::string& arg : args) argv.push_back(arg.c_str());
  MatcherCommandOptions options;
  EXPECT_EQ(ParseMatcherCommandOptions(command, static_cast<int>(argv.size()), argv.data(), &options),
            ParseOutcome::kRun);
  EXPECT_EQ(CheckMatcherCommandOptions(options), "");
  return options;
}

struct Row {
  const char* what;
  std::vector<std::string> args;  // command-line arguments
  void (*set)(MatcherCommandOptions*);  // the same, as Python's keywords set them
  RunFacts facts;
  // Expected: matcher, tables, tau, rematch threshold, the window's upper
  // bound (0: none) and where the rematch runs, block size.
  const char* matcher;
  int num_tables, bits_per_table, tau, rematch, rematch_max;
  RematchPlace where;
  int block_size;
  size_t budget;
  const char* command = "exhaustive_matcher";
};

// A run on device 0 (a pair list; for an exhaustive run `images` images).
RunFacts GpuFacts(size_t images, size_t rows, bool exhaustive, size_t physical = 16 * kGiB) {
  return Facts(images, rows, exhaustive, physical, 0, 80 * kGiB);
}

const std::vector<Row>& Table() {
  constexpr int kCascade = kCascadeTauForScreening;
  constexpr int kPrecision = kCascadeTauForPrecision;
  constexpr int kBucket = kBucketScreeningRematchMinMatches;
  constexpr int kRuns = kDefaultRematchMinMatches;
  constexpr RematchPlace kNowhere = RematchPlace::kNowhere;
  constexpr RematchPlace kMatching = RematchPlace::kMatchingThread;
  constexpr RematchPlace kVerification = RematchPlace::kVerificationThread;
  const auto none = [](MatcherCommandOptions*) {};
  static const std::vector<Row> rows = {
      // On the GPU auto is the cascade with the runs' rematch of every pair
      // that may verify: tables that screen, the bucket screen's threshold.
      {"GPU defaults, 8,192 features: the bucket screen and its threshold", {}, none, GpuFacts(2, 8192, false),
       "cascade", 3, 9, kCascade, kBucket, 0, kMatching, kDefaultBlockSize, 0},
      {"GPU defaults, 16,384 features", {}, none, GpuFacts(2, 16384, false), "cascade", 3, 10, kCascade, kBucket, 0,
       kMatching, kDefaultBlockSize, 0},
      {"GPU defaults, 4,096 features: the bucket screen's 3 x 8", {}, none, GpuFacts(2, 4096, false), "cascade", 3,
       8, kCascade, kBucket, 0, kMatching, kDefaultBlockSize, 0},
      {"GPU defaults, 2,048 features: 8 x 8, deferred rematch from 12", {}, none, GpuFacts(2, 2048, false), "cascade",
       8, 8, kCascade, kRuns, 0, kVerification, kDefaultBlockSize, 0},
      {"GPU, an explicit 12 stays 12", {"--CasHash.exact_rematch_min_matches", "12"},
       [](MatcherCommandOptions* o) { o->cashash.exact_rematch_min_matches = 12; }, GpuFacts(2, 8192, false),
       "cascade", 3, 9, kCascade, 12, 0, kMatching, kDefaultBlockSize, 0},
      {"GPU, no rematch: tables for recall, tau for precision", {"--CasHash.exact_rematch_min_matches", "0"},
       [](MatcherCommandOptions* o) { o->cashash.exact_rematch_min_matches = 0; }, GpuFacts(2, 8192, false),
       "cascade", 8, 7, kPrecision, 0, 0, kNowhere, kDefaultBlockSize, 0},
      {"GPU, tables given: the user's shape and 12", {"--CasHash.num_tables", "6"},
       [](MatcherCommandOptions* o) { o->cashash.num_tables = 6; }, GpuFacts(2, 8192, false), "cascade", 6, 8,
       kCascade, kRuns, 0, kVerification, kDefaultBlockSize, 0},
      {"GPU, a typed window is kept: tables and tau for the cascade's matches",
       {"--CasHash.exact_rematch_max_matches", "96"},
       [](MatcherCommandOptions* o) { o->cashash.exact_rematch_max_matches = 96; }, GpuFacts(2, 8192, false),
       "cascade", 8, 7, kPrecision, kRuns, 96, kVerification, kDefaultBlockSize, 0},
      {"tau given", {"--CasHash.tau", "40", "--CasHash.matcher", "cascade"},
       [](MatcherCommandOptions* o) {
         o->cashash.tau = 40;
         o->cashash.matcher = MatcherType::kCascade;
       },
       GpuFacts(2, 8192, false), "cascade", 3, 9, 40, kBucket, 0, kMatching, kDefaultBlockSize, 0},
      {"the cascade named on the CPU: auto's window and tables for recall", {"--CasHash.matcher", "cascade"},
       [](MatcherCommandOptions* o) { o->cashash.matcher = MatcherType::kCascade; }, Facts(2, 8192, false), "cascade",
       8, 7, kPrecision, kCpuRematchWindowMin, kCpuRematchWindowMax, kMatching, kDefaultBlockSize, 0},
      // On the CPU auto is the cascade's own matches (tables for recall,
      // tau for precision) and the exact rematch of the window [12, 64).
      {"CPU defaults, 8,192 features: the rematch window, the cascade for recall", {}, none, Facts(2, 8192, false),
       "cascade", 8, 7, kPrecision, kCpuRematchWindowMin, kCpuRematchWindowMax, kMatching, kDefaultBlockSize, 0},
      // From 16,384 features the CPU's recall tables have buckets of about 4
      // features (no 64-bit signature); the GPU keeps 8 x 8.
      {"CPU defaults, 16,384 features: buckets of about 4 features", {}, none, Facts(2, 16384, false), "cascade", 19,
       12, kPrecision, kCpuRematchWindowMin, kCpuRematchWindowMax, kMatching, kDefaultBlockSize, 0},
      {"GPU, the same window at 16,384 features: 8 x 8",
       {"--CasHash.exact_rematch_min_matches", "12", "--CasHash.exact_rematch_max_matches", "64"},
       [](MatcherCommandOptions* o) {
         o->cashash.exact_rematch_min_matches = 12;
         o->cashash.exact_rematch_max_matches = 64;
       },
       GpuFacts(2, 16384, false), "cascade", 8, 8, kPrecision, 12, 64, kVerification, kDefaultBlockSize, 0},
      {"CPU, tables given at 16,384 features: the user's", {"--CasHash.num_tables", "8", "--CasHash.bits_per_table", "8"},
       [](MatcherCommandOptions* o) {
         o->cashash.num_tables = 8;
         o->cashash.bits_per_table = 8;
       },
       Facts(2, 16384, false), "cascade", 8, 8, kPrecision, kCpuRematchWindowMin, kCpuRematchWindowMax, kMatching,
       kDefaultBlockSize, 0},
      {"CPU defaults, 4,096 features", {}, none, Facts(2, 4096, false), "cascade", 8, 7, kPrecision,
       kCpuRematchWindowMin, kCpuRematchWindowMax, kMatching, kDefaultBlockSize, 0},
      {"CPU, a typed threshold is kept: no window, the bucket screen", {"--CasHash.exact_rematch_min_matches", "12"},
       [](MatcherCommandOptions* o) { o->cashash.exact_rematch_min_matches = 12; }, Facts(2, 8192, false), "cascade",
       3, 9, kCascade, 12, 0, kMatching, kDefaultBlockSize, 0},
      {"CPU, a typed window is kept", {"--CasHash.exact_rematch_max_matches", "96"},
       [](MatcherCommandOptions* o) { o->cashash.exact_rematch_max_matches = 96; }, Facts(2, 8192, false), "cascade",
       8, 7, kPrecision, kRuns, 96, kMatching, kDefaultBlockSize, 0},
      {"CPU, a typed threshold and window are kept",
       {"--CasHash.exact_rematch_min_matches", "20", "--CasHash.exact_rematch_max_matches", "48"},
       [](MatcherCommandOptions* o) {
         o->cashash.exact_rematch_min_matches = 20;
         o->cashash.exact_rematch_max_matches = 48;
       },
       Facts(2, 8192, false), "cascade", 8, 7, kPrecision, 20, 48, kMatching, kDefaultBlockSize, 0},
      {"CPU, no rematch", {"--CasHash.exact_rematch_min_matches", "0"},
       [](MatcherCommandOptions* o) { o->cashash.exact_rematch_min_matches = 0; }, Facts(2, 8192, false), "cascade",
       8, 7, kPrecision, 0, 0, kNowhere, kDefaultBlockSize, 0},
      {"CPU, brute force named", {"--CasHash.matcher", "bruteforce"},
       [](MatcherCommandOptions* o) { o->cashash.matcher = MatcherType::kBruteForce; }, Facts(2, 8192, false),
       "bruteforce", 3, 9, kCascade, kBucket, 0, kNowhere, kDefaultBlockSize, 0},
      {"guided matching: the cascade for auto, recall, no screen", {}, [](MatcherCommandOptions* o) {
         o->guided.enabled = true;
       },
       Facts(2, 8192, false), "cascade", 8, 7, kPrecision, kRuns, 0, kNowhere, kDefaultBlockSize, 0, "guided_matcher"},
      {"guided matching on the GPU", {}, [](MatcherCommandOptions* o) { o->guided.enabled = true; },
       GpuFacts(2, 8192, false), "cascade", 8, 7, kPrecision, kRuns, 0, kNowhere, kDefaultBlockSize, 0,
       "guided_matcher"},
      {"a pair list keeps a given block size", {"--ExhaustiveMatching.block_size", "20"},
       [](MatcherCommandOptions* o) { o->block_size = 20; }, Facts(2, 8192, false), "cascade", 8, 7, kPrecision,
       kCpuRematchWindowMin, kCpuRematchWindowMax, kMatching, 20, 0},
      {"--max_gpu_memory is every GPU matcher's budget, pair lists too", {"--max_gpu_memory", "512M"},
       [](MatcherCommandOptions* o) { o->max_gpu_memory = "512M"; }, Facts(2, 8192, false, 0, 0, 80 * kGiB),
       "cascade", 3, 9, kCascade, kBucket, 0, kMatching, kDefaultBlockSize, 512 * kMiB},
      {"exhaustive: the block size from memory, at most 50", {}, none, Facts(300, 8192, true, 16 * kGiB), "cascade",
       8, 7, kPrecision, kCpuRematchWindowMin, kCpuRematchWindowMax, kMatching, 50, 0},
      {"exhaustive with little host memory: smaller blocks", {"--max_host_memory", "200M"},
       [](MatcherCommandOptions* o) { o->max_host_memory = "200M"; }, Facts(300, 8192, true, 16 * kGiB), "cascade",
       8, 7, kPrecision, kCpuRematchWindowMin, kCpuRematchWindowMax, kMatching, -1, 0},
      {"exhaustive, a given block size", {"--ExhaustiveMatching.block_size", "30"},
       [](MatcherCommandOptions* o) { o->block_size = 30; }, Facts(300, 8192, true, 16 * kGiB), "cascade", 8, 7,
       kPrecision, kCpuRematchWindowMin, kCpuRematchWindowMax, kMatching, 30, 0},
      {"exhaustive on a GPU with a budget", {"--max_gpu_memory", "8G"},
       [](MatcherCommandOptions* o) { o->max_gpu_memory = "8G"; }, GpuFacts(300, 8192, true), "cascade", 3, 9,
       kCascade, kBucket, 0, kMatching, 50, 8 * kGiB},
      {"exhaustive on a GPU, little host memory", {"--max_host_memory", "200M"},
       [](MatcherCommandOptions* o) { o->max_host_memory = "200M"; }, GpuFacts(300, 8192, true), "cascade", 3, 9,
       kCascade, kBucket, 0, kMatching, -1, 0},
  };
  return rows;
}

TEST(RunResolution, TableOfOptionsAndFactsGivesTheResolvedRun) {
  for (const Row& row : Table()) {
    SCOPED_TRACE(row.what);
    const ResolvedRun run = ResolveRun(FromCommandLine(row.args, row.command), row.facts);
    EXPECT_EQ(MatcherTypeToString(run.options.cashash.matcher), row.matcher);
    EXPECT_EQ(run.options.cashash.num_tables, row.num_tables);
    EXPECT_EQ(run.options.cashash.bits_per_table, row.bits_per_table);
    EXPECT_EQ(run.options.cashash.tau, row.tau);
    EXPECT_EQ(run.options.cashash.exact_rematch_min_matches, row.rematch);
    EXPECT_EQ(run.options.cashash.exact_rematch_max_matches, row.rematch_max);
    EXPECT_EQ(run.rematch.where, row.where) << RematchPlaceName(run.rematch.where);
    EXPECT_EQ(run.rematch.min_matches, run.rematch.enabled() ? static_cast<size_t>(row.rematch) : 0u);
    EXPECT_EQ(run.rematch.max_matches, run.rematch.enabled() ? static_cast<size_t>(row.rematch_max) : 0u);
    if (row.block_size > 0) {
      EXPECT_EQ(run.options.block_size, row.block_size);
    } else {  // smaller than the default
      EXPECT_GE(run.options.block_size, 2);
      EXPECT_LT(run.options.block_size, kDefaultBlockSize);
    }
    EXPECT_EQ(run.schedule.block_size, run.options.block_size);
    EXPECT_EQ(run.gpu_memory_budget_bytes, row.budget);
    EXPECT_EQ(run.gpu_indices, row.facts.gpu_indices);
    EXPECT_EQ(run.gpu_index, row.facts.gpu_indices.empty() ? -1 : row.facts.gpu_indices.front());
    if (row.facts.exhaustive) {
      EXPECT_GT(run.schedule.blocks_per_group, 0);
      EXPECT_GT(run.max_host_bytes, 0u);
      EXPECT_EQ(run.max_gpu_bytes, row.budget > 0 ? row.budget : row.facts.gpu_free_bytes);
    }
  }
}

// Where the exact rematch runs is the policy's, decided once: on one GPU on
// the verification threads (unless the bucket screen leaves the matching
// thread room), on several GPUs on the matching thread, where each chunk's
// rematch is shared out over the devices as its cascade is.
TEST(RunResolution, SeveralGpusRematchOnTheMatchingThread) {
  MatcherCommandOptions options = FromCommandLine({}, "exhaustive_matcher");
  RunFacts one = GpuFacts(2, 2048, false);
  EXPECT_EQ(ResolveRun(options, one).rematch.where, RematchPlace::kVerificationThread);
  RunFacts two = one;
  two.gpu_indices = {0, 1};
  const ResolvedRun run = ResolveRun(options, two);
  EXPECT_EQ(run.rematch.where, RematchPlace::kMatchingThread);
  EXPECT_EQ(run.rematch.min_matches, static_cast<size_t>(kDefaultRematchMinMatches));
  // Everything else is the one GPU's run.
  EXPECT_EQ(run.options.cashash.num_tables, ResolveRun(options, one).options.cashash.num_tables);
}

// The command line and Python fill the same MatcherCommandOptions from the
// same defaults; for the same inputs the runs are identical.
TEST(RunResolution, TheCommandLineAndPythonResolveTheSameInputsIdentically) {
  for (const Row& row : Table()) {
    SCOPED_TRACE(row.what);
    MatcherCommandOptions from_python;  // the module's MatchingOptions()
    from_python.database_path = "x.db";
    if (std::string(row.command) == "guided_matcher") from_python.guided.enabled = true;
    row.set(&from_python);
    EXPECT_EQ(Decisions(ResolveRun(from_python, row.facts)),
              Decisions(ResolveRun(FromCommandLine(row.args, row.command), row.facts)));
  }
}

TEST(RunResolution, MpiRanksSizeWithTheSmallestMemoryOfAll) {
  RunFacts facts = Facts(300, 8192, true, 64 * kGiB, 0, 80 * kGiB);
  facts.smallest_over_ranks = [](uint64_t value) { return value / 4; };  // another rank has a quarter
  const ResolvedRun run = ResolveRun(MatcherCommandOptions(), facts);
  EXPECT_EQ(run.max_host_bytes, 8 * kGiB);
  EXPECT_EQ(run.max_gpu_bytes, 20 * kGiB);
}

TEST(RunResolution, ImagesAboveTheMatchCapAreNamedWithTheOption) {
  // Only the first max_num_matches rows of an image are read: the run says
  // how many images lose features, and which option keeps them.
  RunFacts facts = Facts(10, 40000, true);
  facts.rows_per_image[3] = 20000;
  const ResolvedRun clamped = ResolveRun(MatcherCommandOptions(), facts);
  ASSERT_EQ(clamped.warnings.size(), 1u);
  EXPECT_NE(clamped.warnings[0].find("9 of 10 images have more features than --FeatureMatching.max_num_matches 32768 "
                                     "(up to 40000)"),
            std::string::npos)
      << clamped.warnings[0];
  MatcherCommandOptions raised;
  raised.sift.max_num_matches = 40960;
  EXPECT_TRUE(ResolveRun(raised, facts).warnings.empty());
  EXPECT_TRUE(ResolveRun(MatcherCommandOptions(), Facts(10, 32768, true)).warnings.empty());
}

TEST(RunResolution, NotesSayWhatWasChosenInOrder) {
  MatcherCommandOptions guided;
  guided.guided.enabled = true;
  const ResolvedRun run = ResolveRun(guided, Facts(300, 8192, true));
  ASSERT_EQ(run.notes.size(), 3u);
  EXPECT_EQ(run.notes[0], "Matcher: cascade (guided matching needs it)");
  EXPECT_EQ(run.notes[1].rfind("Hash tables: ", 0), 0u) << run.notes[1];
  EXPECT_EQ(run.notes[2].rfind("Schedule: ", 0), 0u) << run.notes[2];
  MatcherCommandOptions brute_force;
  brute_force.cashash.matcher = MatcherType::kBruteForce;
  EXPECT_TRUE(ResolveRun(brute_force, Facts(2, 8192, false)).notes.empty());
}

TEST(RunResolution, RulesOfTheRematchThresholdAndTheMatcher) {
  EXPECT_EQ(RematchMinMatchesRule(kRematchMinMatchesChosen, false), kDefaultRematchMinMatches);
  EXPECT_EQ(RematchMinMatchesRule(kRematchMinMatchesChosen, true), kBucketScreeningRematchMinMatches);
  EXPECT_EQ(RematchMinMatchesRule(12, true), 12);
  EXPECT_EQ(RematchMinMatchesRule(0, true), 0);
  // Auto: the cascade, with a rule for the rematch on each device; named
  // matchers and typed rematch settings are kept.
  MatcherCommandOptions options;
  const MatcherChoice cpu = MatcherRule(options, false, 8192);
  EXPECT_EQ(cpu.matcher, MatcherType::kCascade);
  EXPECT_EQ(cpu.exact_rematch_min_matches, kCpuRematchWindowMin);
  EXPECT_EQ(cpu.exact_rematch_max_matches, kCpuRematchWindowMax);
  EXPECT_EQ(cpu.reason, "cascade, exact rematch of pairs with 12 to 63 cascade matches (CPU rule)");
  const MatcherChoice gpu = MatcherRule(options, true, 8192, kBucketScreeningRematchMinMatches);
  EXPECT_EQ(gpu.matcher, MatcherType::kCascade);
  EXPECT_EQ(gpu.exact_rematch_min_matches, kBucketScreeningRematchMinMatches);
  EXPECT_EQ(gpu.exact_rematch_max_matches, 0);
  EXPECT_EQ(gpu.reason, "cascade, exact rematch of pairs with at least 8 cascade matches (GPU rule)");
  MatcherCommandOptions typed = options;
  typed.cashash.exact_rematch_min_matches = 12;
  for (const bool on_gpu : {false, true}) {
    const MatcherChoice kept = MatcherRule(typed, on_gpu, 8192);
    EXPECT_EQ(kept.exact_rematch_min_matches, 12);
    EXPECT_EQ(kept.exact_rematch_max_matches, 0);
  }
  MatcherCommandOptions window = options;
  window.cashash.exact_rematch_max_matches = 96;
  EXPECT_EQ(MatcherRule(window, false, 8192).exact_rematch_min_matches, kDefaultRematchMinMatches);
  EXPECT_EQ(MatcherRule(window, false, 8192).exact_rematch_max_matches, 96);
  MatcherCommandOptions guided = options;
  guided.guided.enabled = true;
  MatcherCommandOptions brute_force = options;
  brute_force.cashash.matcher = MatcherType::kBruteForce;
  for (const bool on_gpu : {false, true}) {
    EXPECT_EQ(MatcherRule(guided, on_gpu, 8192).matcher, MatcherType::kCascade);
    EXPECT_EQ(MatcherRule(guided, on_gpu, 8192).exact_rematch_max_matches, 0);
    EXPECT_EQ(MatcherRule(brute_force, on_gpu, 8192).matcher, MatcherType::kBruteForce);
  }
}

// --CasHash.matcher cascade names the algorithm auto chooses, so it gets
// the same run: the CPU's rematch window and tables for recall on the CPU,
// the runs' rematch and the screening tables on the GPU. Only brute force
// is another algorithm.
TEST(RunResolution, TheCascadeNamedResolvesAsAutoOnEachDevice) {
  MatcherCommandOptions cascade;
  cascade.cashash.matcher = MatcherType::kCascade;
  const MatcherCommandOptions automatic;
  for (const size_t rows : {size_t{2048}, size_t{4096}, size_t{8192}, size_t{16384}}) {
    for (const bool exhaustive : {false, true}) {
      const RunFacts cpu = Facts(20, rows, exhaustive);
      EXPECT_EQ(Decisions(ResolveRun(cascade, cpu)), Decisions(ResolveRun(automatic, cpu)))
          << rows << " features on the CPU";
      const RunFacts gpu = Facts(20, rows, exhaustive, 16 * kGiB, 0, 80 * kGiB);
      EXPECT_EQ(Decisions(ResolveRun(cascade, gpu)), Decisions(ResolveRun(automatic, gpu)))
          << rows << " features on the GPU";
    }
  }
}

// A machine whose device 0 cannot run this build's code (an architecture
// the build left out) and whose device 1 can.
DeviceFacts FirstDeviceUnusable() {
  DeviceFacts machine;
  machine.cuda_built = true;
  machine.num_devices = 2;
  machine.usable = [](int gpu_index, std::string* reason) {
    if (gpu_index == 1) return true;
    *reason = "GPU " + std::to_string(gpu_index) + " cannot run this build's GPU code";
    return false;
  };
  return machine;
}

// --FeatureMatching.gpu_index 0,1 where device 0 is unusable: the run
// matches on device 1, so it is resolved with the GPU's rules (a 64-bit
// bucket signature; the CPU's 19 x 12 tables at 16,384 features would not
// fit it) and verifies there too; a warning names device 0.
TEST(RunDevices, ARunIsResolvedWithTheRulesOfTheGpusThatMatch) {
  MatcherCommandOptions options;
  options.gpu_index = "0,1";
  const RunDevices devices = ChooseRunDevices(options, FirstDeviceUnusable());
  EXPECT_EQ(devices.gpu_indices, std::vector<int>{1});
  ASSERT_EQ(devices.warnings.size(), 1u);
  EXPECT_NE(devices.warnings[0].find("device 0: GPU 0 cannot run this build's GPU code"), std::string::npos)
      << devices.warnings[0];
  RunFacts facts = Facts(20, 16384, false);
  facts.gpu_indices = devices.gpu_indices;
  facts.device_warnings = devices.warnings;
  const ResolvedRun run = ResolveRun(options, facts);
  EXPECT_EQ(run.gpu_index, 1);
  EXPECT_LE(run.options.cashash.num_tables * run.options.cashash.bits_per_table, kMaxSignatureBits);
  RunFacts on_device_1 = Facts(20, 16384, false, 16 * kGiB, 1);
  EXPECT_EQ(Decisions(run), Decisions(ResolveRun(options, on_device_1)));
  EXPECT_EQ(run.warnings, devices.warnings);

  // Only the unusable device listed: the CPU, with its rules and a warning.
  options.gpu_index = "0";
  const RunDevices none = ChooseRunDevices(options, FirstDeviceUnusable());
  EXPECT_TRUE(none.gpu_indices.empty());
  ASSERT_EQ(none.warnings.size(), 1u);
  EXPECT_NE(none.warnings[0].find("matching on the CPU"), std::string::npos) << none.warnings[0];
  // Without use_gpu no device is asked for and nothing is said.
  options.use_gpu = false;
  EXPECT_TRUE(ChooseRunDevices(options, FirstDeviceUnusable()).gpu_indices.empty());
  EXPECT_TRUE(ChooseRunDevices(options, FirstDeviceUnusable()).warnings.empty());
}

TEST(RunDevices, MpiRanksOfOneMachineShareItsGpusUnlessOneIsNamed) {
  DeviceFacts machine;
  machine.cuda_built = true;
  machine.num_devices = 4;
  machine.usable = [](int, std::string*) { return true; };
  machine.num_ranks = 8;
  machine.local_rank = 5;
  MatcherCommandOptions options;
  EXPECT_EQ(ChooseRunDevices(options, machine).gpu_indices, std::vector<int>{1});
  options.gpu_index = "2";
  EXPECT_EQ(ChooseRunDevices(options, machine).gpu_indices, std::vector<int>{2});
}

// Two MPI ranks as two threads: Min waits for both values and gives each
// the smaller (distributed::MpiMin), as the job's ranks would.
class TwoRanks {
 public:
  uint64_t Min(uint64_t value) {
    std::unique_lock<std::mutex> lock(mutex_);
    const int round = round_;
    if (arrived_ == 0) smallest_ = value;
    smallest_ = std::min(smallest_, value);
    if (++arrived_ == 2) {
      result_ = smallest_;
      arrived_ = 0;
      ++round_;
      changed_.notify_all();
    } else if (!changed_.wait_for(lock, std::chrono::seconds(10), [&] { return round_ != round; })) {
      ADD_FAILURE() << "the other rank never reduced";
      return value;
    }
    return result_;
  }

 private:
  std::mutex mutex_;
  std::condition_variable changed_;
  int arrived_ = 0, round_ = 0;
  uint64_t smallest_ = 0, result_ = 0;
};

// Under MPI every rank resolves the same run, whichever rank has a GPU: a
// chunk's rows do not depend on the rank that matched it.
TEST(RunResolution, MpiRanksWithAndWithoutAGpuResolveTheSameRun) {
  for (const size_t rows : {size_t{4096}, size_t{8192}, size_t{16384}}) {
    for (const bool exhaustive : {false, true}) {
      TwoRanks ranks;
      RunFacts with_gpu = Facts(40, rows, exhaustive, 16 * kGiB, 0, 80 * kGiB);
      RunFacts without = Facts(40, rows, exhaustive, 16 * kGiB);
      with_gpu.smallest_over_ranks = [&](uint64_t value) { return ranks.Min(value); };
      without.smallest_over_ranks = with_gpu.smallest_over_ranks;
      ResolvedRun run_with, run_without;
      std::thread other([&] { run_without = ResolveRun(MatcherCommandOptions(), without); });
      run_with = ResolveRun(MatcherCommandOptions(), with_gpu);
      other.join();
      const CasHashOptions& a = run_with.options.cashash;
      const CasHashOptions& b = run_without.options.cashash;
      SCOPED_TRACE(std::to_string(rows) + (exhaustive ? " features, exhaustive" : " features, pair list"));
      EXPECT_EQ(a.num_tables, b.num_tables);
      EXPECT_EQ(a.bits_per_table, b.bits_per_table);
      EXPECT_EQ(a.tau, b.tau);
      EXPECT_EQ(a.exact_rematch_min_matches, b.exact_rematch_min_matches);
      EXPECT_EQ(a.exact_rematch_max_matches, b.exact_rematch_max_matches);
      EXPECT_EQ(run_with.options.block_size, run_without.options.block_size);
      EXPECT_EQ(run_with.schedule.blocks_per_group, run_without.schedule.blocks_per_group);
      // The GPU's shapes: the rank with the GPU can run them.
      EXPECT_LE(a.num_tables * a.bits_per_table, kMaxSignatureBits);
    }
  }
}

}  // namespace
}  // namespace colmap
}  // namespace cashash
