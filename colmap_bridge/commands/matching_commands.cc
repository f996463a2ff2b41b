#include "colmap_bridge/commands/matching_commands.h"

#include <algorithm>
#include <cstdio>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <sys/resource.h>

#include "cashash/pipeline/schedule_sizing.h"
#include "colmap_bridge/api/build_info.h"
#include "colmap_bridge/api/command_options.h"
#include "colmap_bridge/api/matching_api.h"
#include "colmap_bridge/api/process_clock.h"
#include "colmap_bridge/api/retrieval_api.h"
#include "colmap_bridge/commands/console.h"

namespace cashash {
namespace colmap {
namespace {

std::string FormatDuration(double seconds) {
  const long s = static_cast<long>(seconds + 0.5);
  std::ostringstream out;
  out << s / 3600 << ":" << std::setw(2) << std::setfill('0') << (s / 60) % 60 << ":" << std::setw(2)
      << std::setfill('0') << s % 60;
  return out.str();
}

void PrintProgress(const PipelineProgress& p) {
  const double rate = p.elapsed_seconds > 0 ? p.pairs_done / p.elapsed_seconds : 0.0;
  const double eta = rate > 0 ? (p.pairs_total - p.pairs_done) / rate : 0.0;
  std::cout << "Matching block [" << p.chunk->block_i + 1 << "/" << p.chunk->num_blocks << ", "
            << p.chunk->block_j + 1 << "/" << p.chunk->num_blocks << "] in " << std::fixed << std::setprecision(3)
            << p.chunk_seconds << "s  (" << p.pairs_done << "/" << p.pairs_total << " pairs, "
            << std::setprecision(1) << 100.0 * p.pairs_done / p.pairs_total << "%, " << rate << " pairs/s, ETA "
            << FormatDuration(eta) << ")" << std::endl;
}

// COLMAP-style console output of a run: heading, notes on stdout, warnings
// on stderr, one line per written block; Ctrl-C stops it cleanly.
MatchingCallbacks ConsoleCallbacks(const std::string& heading, const StopOnInterrupt& interrupt) {
  MatchingCallbacks callbacks;
  callbacks.database_opened = [heading]() {
    PrintHeading(heading);
    std::cout << BuildInfoLine() << std::endl;
  };
  callbacks.info = [](const std::string& text) { std::cout << text << std::endl; };
  callbacks.warning = PrintWarning;
  callbacks.progress = PrintProgress;
  callbacks.stop = interrupt.stop_flag();
  return callbacks;
}

// Largest resident set of this process so far (getrusage; Linux counts KiB).
size_t PeakResidentBytes() {
  struct rusage usage {};
  if (getrusage(RUSAGE_SELF, &usage) != 0) return 0;
  return static_cast<size_t>(usage.ru_maxrss) * 1024;
}

// The phases of the run outside its pipeline that took a millisecond or
// more, in the order they came (PhaseClock).
void PrintPhasesOutsidePipeline(const std::vector<PhaseClock::Phase>& phases) {
  std::ostringstream line;
  line << std::fixed << std::setprecision(3);
  const char* separator = "";
  for (const PhaseClock::Phase& phase : phases) {
    if (phase.seconds < 0.0005) continue;
    line << separator << phase.name << " " << phase.seconds << " s";
    separator = ", ";
  }
  if (*separator != '\0') std::cout << "Outside the pipeline: " << line.str() << std::endl;
}

// Prints the closing summary; returns the exit code (130 when stopped).
int ReportSummary(const MatchingSummary& summary) {
  if (summary.matcher_name.empty()) return EXIT_SUCCESS;  // nothing was matched
  const PipelineStats& stats = summary.pipeline;
  std::cout << std::fixed << std::setprecision(3);
  std::cout << "Elapsed time: " << stats.seconds_total / 60.0 << " [minutes]" << std::endl;
  std::cout << "Summary: " << stats.pairs_done << " pairs in " << stats.seconds_total << " s ("
            << std::setprecision(1) << (stats.seconds_total > 0 ? stats.pairs_done / stats.seconds_total : 0.0)
            << " pairs/s) with " << summary.matcher_name << "; " << stats.raw_matches << " raw matches, "
            << stats.verified_pairs << " verified pairs, " << stats.inlier_matches << " inlier matches"
            << std::endl;
  // Busy time of each stage; loading, hashing and matching share one thread,
  // verification and writing run beside them.
  std::cout << std::setprecision(3) << "Time: loading " << stats.seconds_loading << " s, hashing "
            << stats.seconds_hashing << " s, matching " << stats.seconds_matching << " s, verification "
            << stats.seconds_verification << " s";
  // Calls, not chunks: a call may verify several chunks that waited together.
  if (stats.verification_calls > 0) std::cout << " in " << stats.verification_calls << " calls";
  if (stats.verification_threads > 1) {
    std::cout << " (summed over up to " << stats.verification_threads << " calls at once)";
  }
  // The writer's wall time holds its waits for a core and for the disk;
  // its CPU time is what writing itself cost.
  std::cout << ", writing " << stats.seconds_writing << " s (" << stats.seconds_writing_cpu << " s CPU)" << std::endl;
  // What the user waited for beyond the pipeline: the summary's rate leaves
  // it out.
  const double process_seconds = SecondsSinceProcessStart();
  std::cout << "Process: " << process_seconds << " s so far, " << std::max(0.0, process_seconds - stats.seconds_total)
            << " s of it outside the pipeline" << std::endl;
  PrintPhasesOutsidePipeline(summary.phases_outside_pipeline);
  // Waiting, apart from the busy times: which stage held the others up.
  std::cout << "Waiting: matching for verification " << stats.seconds_matching_wait_queue
            << " s, verification for matching " << stats.seconds_verification_wait_input << " s and for writing "
            << stats.seconds_verification_wait_writer << " s, writing for verification "
            << stats.seconds_writing_wait_input << " s" << std::endl;
  std::cout << "Memory: peak resident " << FormatMemorySize(PeakResidentBytes());
  if (summary.gpu_index >= 0) {
    std::cout << "; GPU " << summary.gpu_index << " at most " << FormatMemorySize(summary.gpu_peak_used_bytes)
              << " of " << FormatMemorySize(summary.gpu_total_bytes) << " in use ("
              << FormatMemorySize(summary.gpu_used_before_bytes) << " before the run; sampled after each block)";
  }
  std::cout << std::endl;
  if (stats.stopped) {
    std::cout << "Stopped after " << stats.pairs_done << " of " << stats.pairs_total
              << " pairs; every finished block is committed, run again to resume." << std::endl;
    return 130;
  }
  return EXIT_SUCCESS;
}

// Parses and checks options; returns -1 when the command should go on.
int PrepareOptions(const std::string& command, int argc, const char* const* argv, MatcherCommandOptions* options) {
  switch (ParseMatcherCommandOptions(command, argc, argv, options)) {
    case ParseOutcome::kHelpShown:
      return EXIT_SUCCESS;
    case ParseOutcome::kError:
      return EXIT_FAILURE;
    case ParseOutcome::kRun:
      break;
  }
  const std::string problem = CheckMatcherCommandOptions(*options);
  if (!problem.empty()) {
    std::cerr << "ERROR: " << problem << std::endl;
    return EXIT_FAILURE;
  }
  return -1;
}

// Runs `body` with Ctrl-C handled; errors become "ERROR: ..." and exit 1.
template <typename Body>
int RunGuarded(const std::string& heading, Body body) {
  const StopOnInterrupt interrupt;
  try {
    return ReportSummary(body(ConsoleCallbacks(heading, interrupt)));
  } catch (const std::exception& e) {
    std::cerr << "ERROR: " << e.what() << std::endl;
  }
  return EXIT_FAILURE;
}

}  // namespace

int RunExhaustiveMatcher(int argc, const char* const* argv) {
  MatcherCommandOptions options;
  const int early = PrepareOptions("exhaustive_matcher", argc, argv, &options);
  if (early >= 0) return early;
  return RunGuarded("Exhaustive feature matching", [&](const MatchingCallbacks& callbacks) {
    return MatchExhaustive(options.database_path, options, callbacks);
  });
}

int RunGuidedMatcher(int argc, const char* const* argv) {
  MatcherCommandOptions options;
  const int early = PrepareOptions("guided_matcher", argc, argv, &options);
  if (early >= 0) return early;
  return RunGuarded("Guided feature matching (Ga-CasHash)", [&](const MatchingCallbacks& callbacks) {
    return MatchExhaustive(options.database_path, options, callbacks);
  });
}

int RunSequentialMatcher(int argc, const char* const* argv) {
  MatcherCommandOptions options;
  const int early = PrepareOptions("sequential_matcher", argc, argv, &options);
  if (early >= 0) return early;
  return RunGuarded("Sequential feature matching", [&](const MatchingCallbacks& callbacks) {
    return MatchSequential(options.database_path, options, callbacks);
  });
}

int RunSpatialMatcher(int argc, const char* const* argv) {
  MatcherCommandOptions options;
  const int early = PrepareOptions("spatial_matcher", argc, argv, &options);
  if (early >= 0) return early;
  return RunGuarded("Spatial feature matching", [&](const MatchingCallbacks& callbacks) {
    return MatchSpatial(options.database_path, options, callbacks);
  });
}

// `command` is "retrieval_matcher" or COLMAP's name, "vocab_tree_matcher".
int RunRetrievalMatcher(const std::string& command, int argc, const char* const* argv) {
  MatcherCommandOptions options;
  const int early = PrepareOptions(command, argc, argv, &options);
  if (early >= 0) return early;
  return RunGuarded("Retrieval feature matching (visual words from the hash codes)",
                    [&](const MatchingCallbacks& callbacks) {
                      return MatchRetrieval(options.database_path, options, callbacks);
                    });
}

int RunMatchesImporter(int argc, const char* const* argv) {
  MatcherCommandOptions options;
  const int early = PrepareOptions("matches_importer", argc, argv, &options);
  if (early >= 0) return early;
  if (options.match_type != "pairs") {
    std::cerr << "ERROR: --match_type '" << options.match_type
              << "' is not supported; cashash matches and verifies 'pairs' lists" << std::endl;
    return EXIT_FAILURE;
  }
  if (options.match_list_path.empty()) {
    std::cerr << "ERROR: --match_list_path is required" << std::endl;
    return EXIT_FAILURE;
  }
  return RunGuarded("Custom feature matching", [&](const MatchingCallbacks& callbacks) {
    return MatchPairList(options.database_path, options.match_list_path, options, callbacks);
  });
}

}  // namespace colmap
}  // namespace cashash
