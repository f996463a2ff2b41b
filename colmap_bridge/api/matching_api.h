// The library entry points behind `cashash exhaustive_matcher`,
// `sequential_matcher`, `spatial_matcher` and `matches_importer`: match the pairs of a COLMAP database and write
// matches and two_view_geometries. The command line and the Python module
// both call these, so they behave and fail alike.
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "cashash/base/phase_clock.h"
#include "cashash/matchers/exact_matcher.h"
#include "cashash/matchers/feature_matcher.h"
#include "cashash/pipeline/exact_rematch_stage.h"
#include "cashash/pipeline/image_retrieval.h"
#include "cashash/pipeline/matching_pipeline.h"
#include "colmap_bridge/api/command_options.h"
#include "colmap_bridge/api/run_gpu_resources.h"
#include "colmap_bridge/api/run_resolution.h"

namespace cashash {
namespace colmap {

// Called from the writer thread after each chunk of pairs is committed.
using ProgressCallback = std::function<void(const PipelineProgress&)>;

// Everything a caller may want to hear about a run besides the result. Unset
// members are skipped, except `warning`, which then goes to stderr.
struct MatchingCallbacks {
  ProgressCallback progress;
  // Once the database is open, before anything is matched (the command line
  // prints its heading here).
  std::function<void()> database_opened;
  // Informational lines, e.g. "Nothing to match." or "Matcher: cpu-cascade".
  std::function<void(const std::string&)> info;
  // Warnings without a "WARNING: " prefix (images without features, CPU
  // fallback when no GPU can be used).
  std::function<void(const std::string&)> warning;
  // When it becomes true the run finishes the chunks in flight, commits them
  // and returns with summary.pipeline.stopped set.
  const std::atomic<bool>* stop = nullptr;
};

// The one way a run says something: `warning` (stderr, "WARNING: ...",
// where the callbacks set none) and `info` (nothing where none is set).
void Warn(const MatchingCallbacks& callbacks, const std::string& text);
void Info(const MatchingCallbacks& callbacks, const std::string& text);

struct MatchingSummary {
  size_t pairs_requested = 0;  // pairs asked for, including those skipped
  size_t pairs_skipped = 0;    // already in the database and not overwritten
  std::string matcher_name;    // "" when nothing was matched
  PipelineStats pipeline;
  // Memory of the GPU the run matched on (gpu_index -1: none or not
  // queryable), from cudaMemGetInfo before the run and after each committed
  // block; the whole device is counted, other processes included.
  int gpu_index = -1;
  size_t gpu_total_bytes = 0;
  size_t gpu_used_before_bytes = 0;  // in use before the matcher was made
  size_t gpu_peak_used_bytes = 0;    // most in use at a sample
  // The run's own books of GPU memory (RunGpuResources): what its owner of
  // the device's memory held at most against the budget, and how often a
  // GPU part went on on the CPU for want of device memory (0: never).
  RunGpuMemoryBooks gpu_memory;
  size_t gpu_memory_fallbacks = 0;
  // Where the call's time outside the pipeline went, phase by phase: before
  // it (opening the database, starting the GPU, making the matcher) and
  // after it (closing the database, freeing GPU memory).
  std::vector<PhaseClock::Phase> phases_outside_pipeline;
  // The run as it was resolved from the options and the database (empty
  // when there was nothing to match, and on MPI ranks > 0).
  ResolvedRun run;
};

// Matches every pair of images of the database (options.database_path is
// ignored). Throws std::invalid_argument when an option is out of range and
// std::runtime_error (DatabaseError included) for unusable input, with the
// messages the command line prints after "ERROR: ".
MatchingSummary MatchExhaustive(const std::string& database_path, const MatcherCommandOptions& options,
                                const MatchingCallbacks& callbacks = {});

// Matches the given pairs of image names (as in table images). Repeated pairs,
// in either order, are matched once.
MatchingSummary MatchPairs(const std::string& database_path,
                           const std::vector<std::pair<std::string, std::string>>& image_name_pairs,
                           const MatcherCommandOptions& options, const MatchingCallbacks& callbacks = {});

// Matches the pairs listed in a matches_importer pair file ("name1 name2" per
// line).
MatchingSummary MatchPairList(const std::string& database_path, const std::string& match_list_path,
                              const MatcherCommandOptions& options, const MatchingCallbacks& callbacks = {});

// Matches the pairs of COLMAP's sequential_matcher (options.sequential):
// images in name order, each with its next overlap images (quadratic
// overlap: 1, 2, 4, ... places on), rig frames expanded; with
// loop_detection also every loop_detection_period-th image with the images
// `retrieval` finds most like it. Without a retrieval of the caller's, the
// run's own: an index over the run's images from their hash codes
// (CreateImageRetrievalForRun, pair_selection.h).
MatchingSummary MatchSequential(const std::string& database_path, const MatcherCommandOptions& options,
                                const MatchingCallbacks& callbacks = {}, ImageRetrieval* retrieval = nullptr);

// Matches the pairs of COLMAP's spatial_matcher (options.spatial): each
// image with a position prior with its nearest neighbours by that prior.
// Images without a prior are named in a warning and left out, as COLMAP
// leaves them out; none with one is an error (std::runtime_error).
MatchingSummary MatchSpatial(const std::string& database_path, const MatcherCommandOptions& options,
                             const MatchingCallbacks& callbacks = {});

// The matcher backend the resolved run asks for: per device of the run
// (run.gpu_indices) a GPU backend, each within run.gpu_memory_budget_bytes
// and inside a fallback to the CPU backend on device-memory errors (whose
// warning goes through `warning`), several under a SplitFeatureMatcher;
// else the CPU backend. The backend both matches (FeatureMatcher) and
// matches exactly from its images (ExactMatcher), whatever it is made of.
//
// --CasHash.matcher auto (the default) never gets here: ResolveRun has
// decided it from the run's data (MatcherRule, run_resolution.h, over
// ChooseAutoMatcher, cashash/matching/matcher_choice.h), and a run still
// naming auto is refused (std::logic_error). With `gpu`, every GPU part
// takes its device memory from that device's owner in it (one budget for
// the run); without, each GPU matcher owns its memory under
// run.gpu_memory_budget_bytes.
std::unique_ptr<MatchingBackend> CreateMatcherForRun(const ResolvedRun& run, const MeanDescriptor& mean,
                                                     const std::function<void(const std::string&)>& warning,
                                                     RunGpuResources* gpu = nullptr);

// The run's exact rematch (run.rematch) over `backend`, the cascade that
// CreateMatcherForRun made: on the verification threads with brute-force
// matchers on the run's GPU for held images that find no device memory.
std::unique_ptr<ExactRematchStage> CreateRematchForRun(const ResolvedRun& run, const MeanDescriptor& mean,
                                                       MatchingBackend* backend, RunGpuResources* gpu = nullptr);

}  // namespace colmap
}  // namespace cashash
