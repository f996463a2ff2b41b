// The one place where a run's settings are decided: the user's options
// (MatcherCommandOptions, the same struct and defaults for the command line
// and Python) and the facts of the database and the machine go in, an
// immutable ResolvedRun comes out. MatchExhaustive, MatchPairs,
// MatchPairList (and so the command line and cashash.match_exhaustive /
// match_pairs) and cashash.match all resolve through ResolveRun.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "cashash/matching/matcher_choice.h"
#include "cashash/pipeline/exact_rematch_stage.h"
#include "cashash/pipeline/schedule_sizing.h"
#include "colmap_bridge/api/command_options.h"

namespace cashash {
namespace colmap {

// What the database and the machine say, gathered before a run is resolved
// (GatherRunFacts in matching_api.cc); tests write them by hand.
struct RunFacts {
  // Feature rows of each image of the run (row counts, no descriptors).
  std::vector<size_t> rows_per_image;
  // Every pair of the images (blocks and groups sized from the memory caps)
  // rather than a list of pairs (chunks of block_size^2 pairs).
  bool exhaustive = true;
  // Physical memory of the machine; 0: unknown (the host cap is then 8 GiB).
  size_t physical_memory_bytes = 0;
  // The devices the run matches and verifies on (ChooseRunDevices,
  // run_devices.h: the usable ones of --FeatureMatching.gpu_index), empty:
  // the CPU; the free memory of the first; and what the choice warned.
  std::vector<int> gpu_indices;
  size_t gpu_free_bytes = 0;
  std::vector<std::string> device_warnings;
  // Under MPI: the smallest of a value over all ranks (distributed::MpiMin),
  // so that every rank resolves the same run: the same matcher, tables and
  // rematch, blocks and groups; unset: one process.
  std::function<uint64_t(uint64_t)> smallest_over_ranks;
};

// The run as it will be carried out. Built by ResolveRun only, and not
// changed after: the plan of a run reads it (run_plan.cc).
struct ResolvedRun {
  // The user's options with every "chosen" value decided: the matcher (auto
  // never stays auto: MatcherRule), the table shape, tau, the exact rematch
  // threshold and its window's upper bound (cashash.exact_rematch_max_matches,
  // 0: none), and the block size.
  MatcherCommandOptions options;
  // The exact rematch (RematchPolicyRule): the threshold and window of
  // options.cashash, and where it runs.
  ExactRematchPolicy rematch;
  // The devices the run matches on (RunFacts::gpu_indices), empty: the
  // CPU; and the first of them, -1: the CPU: the verifier's device.
  std::vector<int> gpu_indices;
  int gpu_index = -1;
  // Device memory each GPU matcher may take (cuda::GpuMatcherConfig::
  // memory_budget_bytes): --max_gpu_memory, 0 when not given (no cap but
  // the device's own memory).
  size_t gpu_memory_budget_bytes = 0;
  // The memory caps the schedule was sized with (exhaustive runs).
  size_t max_host_bytes = 0;
  size_t max_gpu_bytes = 0;
  // Exhaustive runs: blocks, groups and what the matcher may keep
  // (ChooseScheduleSizes); pair lists: block_size only.
  ScheduleSizes schedule;
  // What was chosen and why, in the order the log prints them.
  std::vector<std::string> notes;
  std::vector<std::string> warnings;
};

// Images per block where --ExhaustiveMatching.block_size is not given: an
// exhaustive run derives it from the memory caps, at most this; a pair list
// is cut into chunks of this many images squared.
constexpr int kDefaultBlockSize = 50;

// Resolves the options for a run over the given facts. Under MPI every
// rank resolves the same run from facts reduced over the ranks: the GPU's
// rules where any rank matches on a GPU (the CPU matches the GPU's tables
// and rematch identically, while a GPU cannot run the CPU's fine-bucket
// tables), the CPU's where none does; the smallest memory caps. Throws
// std::invalid_argument when the options cannot fit (ChooseScheduleSizes).
ResolvedRun ResolveRun(const MatcherCommandOptions& options, const RunFacts& facts);

// The exact rematch of a run whose matcher, threshold and window are
// resolved: none for brute force, guided matching (its stage 1 keeps the
// cascade's matches) or a threshold of 0; else on the matching thread where
// the bucket screen leaves that thread idle while the device screens
// (bucket_screen: the rematch then fills time the thread would wait), on
// the CPU, and on several GPUs (each chunk's rematch is shared out over the devices
// as its cascade is); on one GPU on the verification threads, from the
// descriptors the cascade holds on the device, while the matching thread
// goes on with the next chunk.
ExactRematchPolicy RematchPolicyRule(const MatcherCommandOptions& resolved, bool bucket_screen, size_t num_gpus);

// The exact rematch threshold of a run: the user's value where given (>= 0),
// else kDefaultRematchMinMatches, or kBucketScreeningRematchMinMatches with
// the bucket screening tables (fewer tables find fewer of a pair's true
// matches).
int RematchMinMatchesRule(int requested, bool bucket_screen);

// Which matcher the run builds, and for --CasHash.matcher auto its exact
// rematch: ChooseAutoMatcher (cashash/matching/matcher_choice.h) over where
// the run matches and its features per image. Auto is the cascade; on the
// GPU with the runs' rematch threshold, on the CPU with the rematch of the
// pairs in the window [kCpuRematchWindowMin, kCpuRematchWindowMax) of
// cascade matches; guided matching keeps the cascade's matches. The rule
// applies only where the threshold and the window are left to the run
// (threshold kRematchMinMatchesChosen, window max 0); a typed value of
// either is kept on both devices. `runs_threshold` stands for a threshold
// left to the run (RematchMinMatchesRule). Options naming a matcher come
// back unchanged. The reason is the run's "Matcher: " line.
MatcherChoice MatcherRule(const MatcherCommandOptions& options, bool on_gpu, size_t features_per_image,
                          int runs_threshold = kDefaultRematchMinMatches);

}  // namespace colmap
}  // namespace cashash
