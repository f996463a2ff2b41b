// One run of the matcher over a list of pair chunks, read top-down:
//
//   MatchChunks(request, callbacks)
//     PlanRun      the pairs left to match (resume, this rank's share), then
//                  built once: feature cache, matcher and its wrappers,
//                  verifier, writer (or, on ranks > 0, the sender)
//     ExecutePlan  the pipeline over the plan, on one process or many (MPI),
//                  then the run's report
//
// matching_api.cc turns the public calls (MatchExhaustive, MatchPairs,
// MatchPairList) into a RunRequest; this file is the only place where the
// parts of a run are put together.
#pragma once

#include <future>
#include <string>
#include <vector>

#include "cashash/pipeline/pair_generation.h"
#include "colmap_bridge/api/matching_api.h"
#include "colmap_bridge/database_pipeline_io.h"

namespace cashash {
namespace colmap {

struct RunRequest {
  ResolvedRun run;  // ResolveRun (run_resolution.h)
  DatabaseFeatureSource* source = nullptr;
  std::vector<image_t> image_ids;
  // Exhaustive runs: every pair of image_ids, in the order of
  // ScheduledPairChunks with the blocks and groups of run.schedule, each
  // chunk made when the pipeline needs it (ScheduledChunkSource), and the
  // features through a GroupFeatureCache: one group pair in host memory,
  // the next one loaded meanwhile.
  bool exhaustive = false;
  // Otherwise the chunks of a pair list (ListPairChunks), held as they are.
  std::vector<PairChunk> chunks;
  size_t num_pairs_requested = 0;
  std::shared_future<MeanDescriptor> mean;
  // Started by the caller on entry; the run marks its own phases on it and
  // hands them back in MatchingSummary::phases_outside_pipeline.
  PhaseClock clock;
};

// Runs the pipeline over the request's chunks, leaving out pairs already in
// the database unless options.overwrite is set. Under MPI every rank
// computes the same chunks (the database is read by all, read-only, before
// rank 0 opens it for writing) and matches its share; rank 0 writes
// everything (distributed/mpi_distributed.h).
MatchingSummary MatchChunks(RunRequest request, const MatchingCallbacks& callbacks);

}  // namespace colmap
}  // namespace cashash
