// Command-line options of the cashash commands, under COLMAP's names of both
// 3.8 (SiftMatching.*) and 4.x (FeatureMatching.*, SiftMatching.*,
// TwoViewGeometry.*), plus our own CasHash.* options.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "cashash/matching/guided_matching.h"
#include "cashash/matching/matching_options.h"
#include "cashash/geometry/two_view_geometry.h"

namespace cashash {
namespace colmap {

// The runs' exact rematch threshold (CasHashOptions::exact_rematch_min_matches).
constexpr int kDefaultRematchMinMatches = 12;

struct MatcherCommandOptions {
  std::string database_path;
  SiftMatchingOptions sift;
  // --CasHash.matcher defaults to auto here: a run measures both matchers;
  // and the pairs that may verify are matched again exactly. tau 0: chosen
  // for the run (ChooseCascadeTau), 32 while the rematch decides.
  CasHashOptions cashash = [] {
    CasHashOptions options;
    options.matcher = MatcherType::kAuto;
    options.exact_rematch_min_matches = kDefaultRematchMinMatches;
    options.tau = 0;
    return options;
  }();
  // A rematch threshold left at kDefaultRematchMinMatches is replaced by
  // kBucketScreeningRematchMinMatches where the bucket screening shape is
  // chosen (ResolveOptionsForRun). The command line clears this when
  // --CasHash.exact_rematch_min_matches is given, so a typed 12 stays 12;
  // any other threshold is always kept.
  bool rematch_min_matches_from_shape = true;
  // Where a single GPU's exact rematch runs. false: deferred to the
  // verification threads (exact_rematch_feature_matcher.h), which paid
  // while the cascade's screen set the pace. ResolveOptionsForRun sets it
  // with the bucket screening shape, whose screen leaves the matching
  // thread room while verification sets the pace: the 300-image streets
  // ran 9 % (8,192 features) and 3.5 % (16,384) faster with the rematch on
  // the matching thread (H100).
  bool rematch_on_matching_thread = false;
  TwoViewGeometryOptions two_view;
  // Ga-CasHash two-stage epipolar-guided matching (GuidedMatching.*; the
  // guided_matcher command sets enabled).
  GuidedMatchingOptions guided;
  int block_size = 50;  // ExhaustiveMatching.block_size
  // Exhaustive matching derives the block size from the memory caps (at
  // most block_size) instead; the command line sets it unless
  // --ExhaustiveMatching.block_size is given.
  bool block_size_from_memory = false;
  // Memory caps of the three-level scheduling ("16G", "512M", plain numbers
  // are MiB); "" = default: half the machine's physical memory, the GPU's
  // free memory.
  std::string max_host_memory;
  std::string max_gpu_memory;
  bool use_gpu = true;  // COLMAP's default; falls back to the CPU with a warning
  std::string gpu_index = "-1";
  bool skip_geometric_verification = false;
  bool guided_matching = false;  // COLMAP's guided matching: not supported
  bool overwrite = false;        // re-match pairs already in the database
  // COLMAP writes rows for every matched pair, rows = 0 included; 0 writes
  // only pairs with matches and records the others compactly for resuming.
  bool write_empty_pairs = true;
  uint64_t random_seed = 0;
  // matches_importer only.
  std::string match_list_path;
  std::string match_type = "pairs";
};

enum class ParseOutcome { kRun, kHelpShown, kError };

// Parses argv (after the command name). On error prints one line naming the
// option to stderr. `command` is "exhaustive_matcher", "guided_matcher" or
// "matches_importer".
ParseOutcome ParseMatcherCommandOptions(const std::string& command, int argc, const char* const* argv,
                                        MatcherCommandOptions* options);

// Checks every option's range; returns "" or a message naming the option.
std::string CheckMatcherCommandOptions(const MatcherCommandOptions& options);

}  // namespace colmap
}  // namespace cashash
