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
#include "cashash/pipeline/sequential_pairs.h"
#include "cashash/pipeline/spatial_pairs.h"
#include "cashash/retrieval/retrieval_options.h"

namespace cashash {
namespace colmap {

// The runs' exact rematch threshold where it is not given
// (RematchMinMatchesRule, run_resolution.h).
constexpr int kDefaultRematchMinMatches = 12;

// The user's options of a run: the command line parses into it, Python's
// MatchingOptions is it, and its defaults are the one set of user-facing
// defaults. Values "chosen for the run" (0 tables, tau 0, block size 0,
// rematch threshold -1) are decided by ResolveRun (run_resolution.h) from
// the database and the machine.
struct MatcherCommandOptions {
  std::string database_path;
  SiftMatchingOptions sift;
  // CasHashOptions' own defaults: matcher auto, tables, tau and the rematch
  // threshold chosen for the run (matching_options.h). MatcherRule decides
  // auto from the run's data: the cascade, whose pairs that may verify are
  // matched again exactly (threshold chosen for the run; on the CPU only
  // those in a window of cascade match counts); tau 32 while the rematch
  // decides (ChooseCascadeTau).
  CasHashOptions cashash;
  TwoViewGeometryOptions two_view;
  // Ga-CasHash two-stage epipolar-guided matching (GuidedMatching.*; the
  // guided_matcher command sets enabled).
  GuidedMatchingOptions guided;
  // ExhaustiveMatching.block_size. 0: chosen; exhaustive matching derives
  // it from the memory caps (at most kDefaultBlockSize, 50), a pair list is
  // cut into chunks of 50 x 50 pairs.
  int block_size = 0;
  // Memory caps of the three-level scheduling ("16G", "512M", plain numbers
  // are MiB); "" = default: half the machine's physical memory, the GPU's
  // free memory. max_gpu_memory is also each GPU matcher's budget
  // (ResolvedRun::gpu_memory_budget_bytes), exhaustive runs and pair lists
  // alike.
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
  // The writer's transactions: chunks are committed together once a
  // transaction has been open this many seconds (0: each chunk alone). A
  // kill -9 loses the chunks not yet committed (matched again on resume).
  double database_commit_seconds = 1.0;
  // PRAGMA synchronous of the writer: FULL (SQLite's default), NORMAL or
  // OFF; DiskSync (database.h) says what NORMAL and OFF risk on a power loss.
  std::string database_synchronous = "FULL";
  uint64_t random_seed = 0;
  // sequential_matcher only (SequentialMatching.*).
  SequentialPairingOptions sequential;
  // spatial_matcher only (SpatialMatching.*).
  SpatialPairingOptions spatial;
  // matches_importer only.
  std::string match_list_path;
  std::string match_type = "pairs";
  // retrieval_matcher / vocab_tree_matcher (VocabTreeMatching.*,
  // Retrieval.*): which pairs retrieval chooses. vocab_tree_path is
  // COLMAP's and is not used (a warning says so): the vocabulary comes from
  // the hash codes. transitive_rounds > 0: after the retrieved pairs, the
  // pairs the verified graph implies are matched, this many rounds, as
  // COLMAP's transitive_matcher does.
  RetrievalOptions retrieval;
  std::string vocab_tree_path;
  int vocab_tree_num_checks = 256;  // COLMAP's VocabTreeMatching.num_checks: accepted, not used
  int transitive_rounds = 0;
  // Not empty: each chunk's stage intervals are written to this CSV file
  // (pipeline_trace.h; under MPI each rank writes PATH.rankN), to read a
  // run's critical path with scripts/bench/pipeline_trace_summary.py.
  std::string pipeline_trace_path;
  // Chunks the GPU verifier keeps on the device at once, 1 to 8 (not a
  // command-line option): 2 verifies most where verification sets the pace
  // and costs little where matching does (cuda::GpuVerifierConfig).
  int gpu_verifications_in_flight = 2;
};

enum class ParseOutcome { kRun, kHelpShown, kError };

// Parses argv (after the command name). On error prints one line naming the
// option to stderr. `command` is "exhaustive_matcher", "guided_matcher",
// "matches_importer", "sequential_matcher", "spatial_matcher",
// "retrieval_matcher" or "vocab_tree_matcher".
ParseOutcome ParseMatcherCommandOptions(const std::string& command, int argc, const char* const* argv,
                                        MatcherCommandOptions* options);

// Checks every option's range; returns "" or a message naming the option.
std::string CheckMatcherCommandOptions(const MatcherCommandOptions& options);

// The same for a run without a database (cashash.match): every option but
// database_path.
std::string CheckRunOptions(const MatcherCommandOptions& options);

// The devices of --FeatureMatching.gpu_index: "-1" (the first device, 0),
// "2", or a comma-separated list "0,1" (one matcher per device), repeats
// dropped. The one parser of the option: returns "" or a message naming it.
std::string ParseGpuIndices(const std::string& gpu_index, std::vector<int>* indices);

}  // namespace colmap
}  // namespace cashash
