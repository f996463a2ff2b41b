#include "colmap_bridge/api/run_resolution.h"

#include <algorithm>
#include <limits>
#include <string>
#include <vector>

#include "cashash/matching/table_shape.h"

namespace cashash {
namespace colmap {
namespace {

uint64_t SmallestOverRanks(const RunFacts& facts, uint64_t value) {
  return facts.smallest_over_ranks ? facts.smallest_over_ranks(value) : value;
}

// The memory caps and the blocks and groups of an exhaustive run; notes and
// warnings say what was chosen.
void ResolveSchedule(const RunFacts& facts, ResolvedRun* run) {
  const MatcherCommandOptions& options = run->options;
  ScheduleLimits limits;
  if (options.max_host_memory.empty()) {
    limits.max_host_bytes = facts.physical_memory_bytes > 0 ? facts.physical_memory_bytes / 2 : (size_t{8} << 30);
  } else {
    ParseMemorySize(options.max_host_memory, &limits.max_host_bytes);  // checked with the options
  }
  // A rank on the CPU has no GPU cap: it takes the others' smallest.
  uint64_t gpu_cap = std::numeric_limits<uint64_t>::max();
  if (!facts.gpu_indices.empty()) {
    if (options.max_gpu_memory.empty()) {
      gpu_cap = facts.gpu_free_bytes;
      // No budget: the images may take the share they took before the
      // rematch and the verifier shared one (the rest of the card, a
      // quarter, is far more than those need).
      limits.gpu_image_share = ScheduleLimits::kImageShareWithoutBudget;
      limits.gpu_without_budget = true;
    } else {
      size_t bytes = 0;
      ParseMemorySize(options.max_gpu_memory, &bytes);  // checked with the options
      gpu_cap = bytes;
    }
  }
  // Ranks must cut the same blocks and groups: the smallest caps of all.
  limits.max_host_bytes = SmallestOverRanks(facts, limits.max_host_bytes);
  gpu_cap = SmallestOverRanks(facts, gpu_cap);
  limits.max_gpu_bytes = gpu_cap == std::numeric_limits<uint64_t>::max() ? 0 : static_cast<size_t>(gpu_cap);
  const bool block_size_chosen = options.block_size == 0;
  limits.block_size = options.block_size;
  limits.max_num_matches = options.sift.max_num_matches;
  limits.num_tables = options.cashash.num_tables;
  ScheduleSizes sizes = ChooseScheduleSizes(facts.rows_per_image, limits);
  if (block_size_chosen) sizes.block_size = std::min(sizes.block_size, kDefaultBlockSize);
  if (!sizes.warning.empty()) run->warnings.push_back(sizes.warning);
  const size_t num_images = facts.rows_per_image.size();
  const size_t num_blocks = (num_images + sizes.block_size - 1) / sizes.block_size;
  const size_t num_groups = (num_blocks + sizes.blocks_per_group - 1) / sizes.blocks_per_group;
  run->notes.push_back(
      "Schedule: blocks of " + std::to_string(sizes.block_size) + " images, groups of " +
      std::to_string(sizes.blocks_per_group) + " blocks (" + std::to_string(num_blocks) + " blocks, " +
      std::to_string(num_groups) + " groups); host memory " + FormatMemorySize(sizes.predicted_host_bytes) +
      (sizes.kept_host_bytes > 0 ? " (and up to " + FormatMemorySize(sizes.kept_host_bytes) + " for kept images)"
                                 : std::string()) +
      " of " + FormatMemorySize(limits.max_host_bytes) +
      (limits.max_gpu_bytes > 0 ? ", GPU memory for images " + FormatMemorySize(sizes.predicted_gpu_bytes) + " of " +
                                      FormatMemorySize(limits.max_gpu_bytes)
                                : std::string()));
  run->max_host_bytes = limits.max_host_bytes;
  run->max_gpu_bytes = limits.max_gpu_bytes;
  run->options.block_size = sizes.block_size;
  run->schedule = sizes;
}

}  // namespace

ExactRematchPolicy RematchPolicyRule(const MatcherCommandOptions& resolved, bool bucket_screen, size_t num_gpus) {
  ExactRematchPolicy policy;
  const CasHashOptions& cashash = resolved.cashash;
  if (cashash.matcher != MatcherType::kCascade || resolved.guided.enabled || cashash.exact_rematch_min_matches <= 0) {
    return policy;
  }
  policy.min_matches = static_cast<size_t>(cashash.exact_rematch_min_matches);
  policy.max_matches = static_cast<size_t>(std::max(0, cashash.exact_rematch_max_matches));
  policy.where = bucket_screen || num_gpus != 1 ? RematchPlace::kMatchingThread : RematchPlace::kVerificationThread;
  return policy;
}

int RematchMinMatchesRule(int requested, bool bucket_screen) {
  if (requested >= 0) return requested;
  return bucket_screen ? kBucketScreeningRematchMinMatches : kDefaultRematchMinMatches;
}

MatcherChoice MatcherRule(const MatcherCommandOptions& options, bool on_gpu, size_t features_per_image,
                          int runs_threshold) {
  MatcherChoiceInput input;
  input.on_gpu = on_gpu;
  input.features_per_image = features_per_image;
  input.rematch_from_rule = options.cashash.exact_rematch_min_matches == kRematchMinMatchesChosen &&
                            options.cashash.exact_rematch_max_matches == 0;
  input.guided = options.guided.enabled;
  CasHashOptions cashash = options.cashash;
  if (cashash.exact_rematch_min_matches == kRematchMinMatchesChosen) cashash.exact_rematch_min_matches = runs_threshold;
  return ChooseAutoMatcher(cashash, input);
}

namespace {

// COLMAP's GPU matcher clamps an image's features to max_num_matches and
// says so; both of cashash's backends read only that many rows of an image,
// so a run names how many images lose features and how to keep them (empty
// when none does).
std::string ClampedFeaturesWarning(const std::vector<size_t>& rows_per_image, int max_num_matches) {
  const size_t cap = static_cast<size_t>(std::max(1, max_num_matches));
  size_t clamped = 0;
  size_t largest = 0;
  for (size_t rows : rows_per_image) {
    if (rows > cap) ++clamped;
    largest = std::max(largest, rows);
  }
  if (clamped == 0) return std::string();
  return std::to_string(clamped) + " of " + std::to_string(rows_per_image.size()) +
         " images have more features than --FeatureMatching.max_num_matches " + std::to_string(cap) + " (up to " +
         std::to_string(largest) + "); only the first " + std::to_string(cap) +
         " of each are matched, as COLMAP's GPU matcher does; raise --FeatureMatching.max_num_matches to match them all";
}

}  // namespace

ResolvedRun ResolveRun(const MatcherCommandOptions& options, const RunFacts& facts) {
  ResolvedRun run;
  run.options = options;
  CasHashOptions& cashash = run.options.cashash;
  const bool guided = options.guided.enabled;
  // The GPU's rules where any rank matches on a GPU (ResolveRun's header).
  const bool on_gpu = SmallestOverRanks(facts, facts.gpu_indices.empty() ? 1 : 0) == 0;
  const size_t features = TypicalFeatureCount(facts.rows_per_image, options.sift.max_num_matches);

  // The matcher and, for auto, the rematch threshold and window; then the
  // tables: for recall where the cascade's matches are kept (no rematch, a
  // window with an upper bound, guided matching), one bit coarser where the
  // exact rematch decides and the cascade only screens.
  MatcherChoice choice = MatcherRule(options, on_gpu, features);
  const TableShapeGoal goal =
      CascadeOnlyScreens(choice.exact_rematch_min_matches, guided, choice.exact_rematch_max_matches)
          ? TableShapeGoal::kScreening
          : TableShapeGoal::kRecall;
  const int requested_tau = cashash.tau;
  const TableShapeBackend backend = on_gpu ? TableShapeBackend::kAny : TableShapeBackend::kCpu;
  cashash = ResolveTableShape(cashash, features, goal, backend);
  // Fewer tables find fewer of a pair's true matches: a threshold left to
  // the run is the one the bucket screening shape was measured with
  // (table_shape.h); its screen is light, so the matching thread has room
  // for the rematch.
  const bool bucket_screen =
      IsBucketScreeningShape(features, options.cashash.num_tables, options.cashash.bits_per_table, goal);
  const int runs_threshold = RematchMinMatchesRule(kRematchMinMatchesChosen, bucket_screen);
  if (runs_threshold != kDefaultRematchMinMatches) choice = MatcherRule(options, on_gpu, features, runs_threshold);
  cashash.matcher = choice.matcher;
  cashash.exact_rematch_min_matches = choice.exact_rematch_min_matches;
  cashash.exact_rematch_max_matches = choice.exact_rematch_max_matches;
  const bool rematch_from_shape = options.cashash.exact_rematch_min_matches == kRematchMinMatchesChosen &&
                                  cashash.exact_rematch_min_matches != kDefaultRematchMinMatches;
  if (options.cashash.matcher != MatcherType::kBruteForce) run.notes.push_back("Matcher: " + choice.reason);
  // tau: where not given, for screening while the exact rematch decides the
  // pairs that may verify, for precision where the cascade's matches are kept.
  if (cashash.tau <= 0) {
    cashash.tau = ChooseCascadeTau(cashash.exact_rematch_min_matches, guided, cashash.exact_rematch_max_matches);
  }
  if (cashash.matcher != MatcherType::kBruteForce) {
    std::string text =
        DescribeTableShape(options.cashash, cashash, features, facts.rows_per_image.size(), goal, backend);
    text += "; tau " + std::to_string(cashash.tau);
    if (requested_tau == kTauChosen) {
      text += cashash.tau == kCascadeTauForScreening ? " (chosen: the exact rematch decides the pairs that may verify)"
                                                     : " (chosen: the cascade's own matches are kept)";
    }
    if (rematch_from_shape) {
      text += "; exact rematch from " + std::to_string(cashash.exact_rematch_min_matches) +
              " cascade matches (chosen for these tables)";
    }
    run.notes.push_back(text);
  }

  run.gpu_indices = facts.gpu_indices;
  run.rematch = RematchPolicyRule(run.options, bucket_screen, run.gpu_indices.size());
  run.gpu_index = facts.gpu_indices.empty() ? -1 : facts.gpu_indices.front();
  run.warnings.insert(run.warnings.begin(), facts.device_warnings.begin(), facts.device_warnings.end());
  const std::string clamped = ClampedFeaturesWarning(facts.rows_per_image, options.sift.max_num_matches);
  if (!clamped.empty()) run.warnings.push_back(clamped);
  if (!options.max_gpu_memory.empty()) {
    ParseMemorySize(options.max_gpu_memory, &run.gpu_memory_budget_bytes);  // checked with the options
  }
  if (facts.exhaustive) {
    ResolveSchedule(facts, &run);
  } else {
    run.options.block_size = options.block_size > 0 ? options.block_size : kDefaultBlockSize;
    run.schedule.block_size = run.options.block_size;
  }
  return run;
}

}  // namespace colmap
}  // namespace cashash
