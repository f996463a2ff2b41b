#include "colmap_bridge/api/run_plan.h"

#include <algorithm>
#include <chrono>
#include <iomanip>
#include <memory>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

#include "cashash/base/caching_block_allocator.h"
#include "cashash/matchers/retaining_feature_matcher.h"
#include "cashash/matching/guided_matching.h"
#include "cashash/pipeline/exact_rematch_stage.h"
#include "cashash/pipeline/feature_cache.h"
#include "cashash/pipeline/pair_chunk_source.h"
#include "cashash/pipeline/pair_triangle.h"
#include "cashash/pipeline/pipeline_trace.h"
#include "cashash/pipeline/schedule_sizing.h"
#include "colmap_bridge/api/gpu_memory_query.h"
#include "colmap_bridge/api/run_gpu_resources.h"
#include "colmap_bridge/api/verifier_selection.h"
#include "colmap_bridge/completed_pairs.h"
#include "distributed/mpi_distributed.h"
#include "distributed/mpi_world.h"

namespace cashash {
namespace colmap {

using distributed::ChunksOfRank;
using distributed::LockedSink;
using distributed::MpiAbortJob;
using distributed::MpiBarrier;
using distributed::MpiMax;
using distributed::MpiMin;
using distributed::MpiRank;
using distributed::MpiResultReceiver;
using distributed::MpiResultSender;
using distributed::MpiSize;
using distributed::RankReport;

namespace {

void WarnAboutSmallImages(DatabaseFeatureSource& source, const std::vector<image_t>& image_ids,
                          const MatchingCallbacks& callbacks) {
  for (image_t image_id : image_ids) {
    const size_t rows = source.database().NumDescriptors(image_id);
    if (rows < 2) {
      Warn(callbacks, "image " + std::to_string(image_id) + " (" + source.image(image_id).name + ") has " +
                          std::to_string(rows) + " feature" + (rows == 1 ? "" : "s") +
                          "; its pairs get empty matches");
    }
  }
}

// Adds the statistics of another rank's pipeline to rank 0's: counts add
// up, times are the longest rank's.
void MergeStats(const PipelineStats& other, PipelineStats* stats) {
  stats->pairs_total += other.pairs_total;
  stats->pairs_done += other.pairs_done;
  stats->raw_matches += other.raw_matches;
  stats->verified_pairs += other.verified_pairs;
  stats->inlier_matches += other.inlier_matches;
  stats->verification_calls += other.verification_calls;
  stats->seconds_total = std::max(stats->seconds_total, other.seconds_total);
  stats->seconds_loading = std::max(stats->seconds_loading, other.seconds_loading);
  stats->seconds_hashing = std::max(stats->seconds_hashing, other.seconds_hashing);
  stats->seconds_matching = std::max(stats->seconds_matching, other.seconds_matching);
  stats->seconds_verification = std::max(stats->seconds_verification, other.seconds_verification);
  stats->seconds_writing = std::max(stats->seconds_writing, other.seconds_writing);
  stats->seconds_writing_cpu = std::max(stats->seconds_writing_cpu, other.seconds_writing_cpu);
  stats->seconds_matching_wait_queue = std::max(stats->seconds_matching_wait_queue, other.seconds_matching_wait_queue);
  stats->seconds_verification_wait_input =
      std::max(stats->seconds_verification_wait_input, other.seconds_verification_wait_input);
  stats->seconds_verification_wait_writer =
      std::max(stats->seconds_verification_wait_writer, other.seconds_verification_wait_writer);
  stats->seconds_writing_wait_input = std::max(stats->seconds_writing_wait_input, other.seconds_writing_wait_input);
  stats->stopped = stats->stopped || other.stopped;
}

// Device memory in use on the run's GPU: before the matcher exists, then
// after every written block (the writer thread, and the MPI receiver's).
class GpuMemorySampler {
 public:
  explicit GpuMemorySampler(int gpu_index) : gpu_index_(gpu_index) {
    size_t free_bytes = 0;
    if (gpu_index_ < 0 || !GpuMemoryInfo(gpu_index_, &free_bytes, &total_bytes_)) {
      gpu_index_ = -1;
      return;
    }
    before_bytes_ = total_bytes_ - free_bytes;
    peak_bytes_ = before_bytes_;
  }

  void Sample() {
    if (gpu_index_ < 0) return;
    size_t free_bytes = 0, total_bytes = 0;
    if (!GpuMemoryInfo(gpu_index_, &free_bytes, &total_bytes)) return;
    std::lock_guard<std::mutex> lock(mutex_);
    peak_bytes_ = std::max(peak_bytes_, total_bytes - free_bytes);
  }

  void Fill(MatchingSummary* summary) {
    std::lock_guard<std::mutex> lock(mutex_);
    summary->gpu_index = gpu_index_;
    summary->gpu_total_bytes = total_bytes_;
    summary->gpu_used_before_bytes = before_bytes_;
    summary->gpu_peak_used_bytes = peak_bytes_;
  }

 private:
  int gpu_index_;
  size_t total_bytes_ = 0, before_bytes_ = 0, peak_bytes_ = 0;
  std::mutex mutex_;
};

// What this process matches: the pairs not yet in the database, and of
// those this rank's chunks. Exhaustive runs make their chunks as the
// pipeline asks for them; pair lists hold theirs.
struct RunShare {
  int rank = 0;
  int num_ranks = 1;
  size_t num_pairs = 0;  // of every rank
  size_t pairs_skipped = 0;
  std::unique_ptr<std::vector<PairChunk>> listed;  // a pair list's chunks left
  std::unique_ptr<PairChunkSource> all;            // every rank's chunks left
  std::unique_ptr<PairChunkSource> mine;           // this rank's, under MPI

  const PairChunkSource& my_chunks() const { return mine ? *mine : *all; }
};

// Everything a run is made of, built once by PlanRun. Members point into
// each other (the pipeline's features into the cache, wrappers into the
// matcher), so a plan is neither copied nor moved once built.
struct RunPlan {
  explicit RunPlan(const ResolvedRun& resolved) : run(resolved) {}
  RunShare share;
  const ResolvedRun& run;  // the request's, as ResolveRun made it
  std::unique_ptr<GroupFeatureCache> cache;
  FeatureSource* features = nullptr;
  std::unique_ptr<GpuMemorySampler> gpu_memory;
  // One owner of device memory per GPU, shared by the matchers, the
  // rematch and the verifier under --max_gpu_memory.
  std::unique_ptr<RunGpuResources> gpu_resources;
  std::unique_ptr<FeatureMatcher> matcher;
  // The exact rematch over the backend inside matcher (none: guided runs).
  std::unique_ptr<ExactRematchStage> rematch;
  GuidedFeatureMatcher* guided = nullptr;       // inside matcher, if any
  RetainingFeatureMatcher* retaining = nullptr;  // inside matcher, if any
  size_t keep_bytes = 0;                          // the retaining matcher's cap
  // Rank 0 writes (through a lock: its pipeline and the MPI receiver);
  // the other ranks send.
  std::unique_ptr<DatabaseResultSink> database_sink;
  std::unique_ptr<LockedSink> locked_sink;
  std::unique_ptr<MpiResultSender> sender;
  ResultSink* sink = nullptr;
  std::unique_ptr<BatchVerifier> verifier;  // none when verification is skipped
};

// The pairs left of the request's after resume, checked to be the same on
// every rank, and this rank's share of them. An exhaustive run keeps one
// bit per pair of the run, and only once the database holds one of them;
// a pair list is thinned as it is.
RunShare ShareOfRun(RunRequest& request, const MatchingCallbacks& callbacks) {
  RunShare share;
  share.rank = MpiRank();
  share.num_ranks = MpiSize();
  const bool resume = !request.run.options.overwrite;
  if (request.exhaustive) {
    PairTriangle done;
    if (resume) {
      CompletedPairs completed = ReadCompletedPairs(request.source->database(), request.image_ids);
      if (completed.num_completed() > 0) done = completed.TakeTriangle();
    }
    share.all = std::make_unique<ScheduledChunkSource>(request.image_ids, request.run.schedule.block_size,
                                                       request.run.schedule.blocks_per_group, std::move(done));
  } else {
    share.listed = std::make_unique<std::vector<PairChunk>>(std::move(request.chunks));
    if (resume) {
      const CompletedPairs done = ReadCompletedPairs(request.source->database(), request.image_ids, *share.listed);
      if (done.num_completed() > 0) {
        *share.listed = RemovePairs(std::move(*share.listed),
                                    [&](const ImagePair& pair) { return done.Contains(pair.first, pair.second); });
      }
    }
    share.all = std::make_unique<ChunkList>(share.listed.get());
  }
  if (share.num_ranks > 1) {
    const uint64_t checksum = share.all->Checksum();
    if (MpiMin(checksum) != MpiMax(checksum)) {
      throw std::runtime_error("MPI ranks disagree on the pairs to match (same database and options on every rank?)");
    }
    // Every rank has read the completed pairs: rank 0 may start writing.
    MpiBarrier();
  }
  share.num_pairs = share.all->num_pairs();
  share.pairs_skipped = request.num_pairs_requested - share.num_pairs;
  if (share.pairs_skipped > 0) {
    Info(callbacks, "Skipping " + std::to_string(share.pairs_skipped) + " of " +
                        std::to_string(request.num_pairs_requested) +
                        " pairs already in the database (use --overwrite 1 to match them again)");
  }
  if (share.num_ranks > 1) share.mine = std::make_unique<ChunksOfRank>(share.all.get(), share.rank, share.num_ranks);
  return share;
}

// The run's matcher: the backend the options ask for, inside Ga-CasHash's
// two stages when guided matching is on, inside a RetainingFeatureMatcher
// when released images are to be kept.
void ComposeMatcher(const RunRequest& request, const MeanDescriptor& mean, const MatchingCallbacks& callbacks,
                    RunPlan* plan) {
  const MatcherCommandOptions& options = plan->run.options;
  std::unique_ptr<MatchingBackend> backend = CreateMatcherForRun(
      plan->run, mean, [&](const std::string& text) { Warn(callbacks, text); }, plan->gpu_resources.get());
  // Guided matching (Ga-CasHash, cashash/matching/guided_matching.h): a
  // second matcher for the top-scale subsets and the stage-1 F estimator;
  // the pipeline adds its images with their keypoints (the guided
  // matcher's traits ask for them).
  if (options.guided.enabled) {
    auto guided = std::make_unique<GuidedFeatureMatcher>(
        std::move(backend), CreateMatcherForRun(plan->run, mean, nullptr, plan->gpu_resources.get()),
        CreateFundamentalEstimatorOnDevice(options, plan->run.gpu_index, plan->gpu_resources.get()), options.guided,
        options.sift.max_num_matches, options.two_view.random_seed, options.sift.num_threads);
    plan->guided = guided.get();
    plan->matcher = std::move(guided);
  } else {
    plan->rematch = CreateRematchForRun(plan->run, mean, backend.get(), plan->gpu_resources.get());
    plan->matcher = std::move(backend);
  }
  const size_t keep_bytes = request.run.schedule.matcher_keep_bytes;
  if (keep_bytes > 0) {
    const size_t max_rows = static_cast<size_t>(std::max(1, options.sift.max_num_matches));
    // A guided matcher also holds the top-scale subset and the positions.
    const double share = options.guided.enabled ? 1.0 + options.guided.top_scale_fraction : 1.0;
    const size_t position_bytes = options.guided.enabled ? 24 : 0;
    auto keeping = std::make_unique<RetainingFeatureMatcher>(
        std::move(plan->matcher), keep_bytes,
        [max_rows, tables = options.cashash.num_tables, share, position_bytes,
         on_gpu = plan->run.gpu_index >= 0,
         budget = plan->run.gpu_memory_budget_bytes > 0](const FeatureDescriptors& d) {
          const size_t rows = std::min(d.rows(), max_rows);
          // On the GPU, the size class of the image's block: what the
          // device's owner of memory counts (ScheduleSizes does the same).
          size_t bytes = MatcherBytesPerImage(rows, tables);
          if (on_gpu) {
            bytes = budget ? CachingBlockAllocator::SizeClass(bytes) : CachingBlockAllocator::SlabBlockClass(bytes);
          }
          return static_cast<size_t>(share * static_cast<double>(bytes)) + rows * position_bytes;
        });
    plan->retaining = keeping.get();
    plan->keep_bytes = keep_bytes;
    plan->matcher = std::move(keeping);
  }
}

// Rank 0 alone opens the database for writing (and takes the writer lock);
// the other ranks send their results to it.
void OpenSink(RunPlan* plan) {
  const MatcherCommandOptions& options = plan->run.options;
  if (plan->share.rank == 0) {
    DatabaseResultSink::Options writing;
    writing.write_two_view_geometries = !options.skip_geometric_verification;
    writing.write_empty_pairs = options.write_empty_pairs;
    writing.replace_existing = options.overwrite;
    writing.commit_seconds = options.database_commit_seconds;
    ParseDiskSync(options.database_synchronous, &writing.disk_sync);  // checked with the options
    plan->database_sink = std::make_unique<DatabaseResultSink>(options.database_path, writing);
    plan->locked_sink = std::make_unique<LockedSink>(plan->database_sink.get());
    plan->sink = plan->locked_sink.get();
  } else {
    plan->sender = std::make_unique<MpiResultSender>(&plan->share.my_chunks());
    plan->sink = plan->sender.get();
  }
}

// Builds everything the run needs, in the order that lets slow starts
// overlap: the feature cache first (its thread reads the first chunk's
// features while the GPU, the matcher and the verifier start: the setup
// takes about 0.3 s, longer than the matching thread's first wait for
// features at 300 images), then the device, the matcher, the writer
// and the verifier.
void PlanRun(RunRequest& request, RunShare share, const MatchingCallbacks& callbacks, RunPlan* plan) {
  PhaseClock& clock = request.clock;
  plan->share = std::move(share);
  if (plan->share.rank == 0) WarnAboutSmallImages(*request.source, request.image_ids, callbacks);
  if (request.exhaustive) {
    plan->cache = std::make_unique<GroupFeatureCache>(request.source, plan->share.my_chunks());
  }
  plan->features = plan->cache ? static_cast<FeatureSource*>(plan->cache.get()) : request.source;
  clock.Mark("starting the feature reader");

  plan->gpu_memory = std::make_unique<GpuMemorySampler>(plan->run.gpu_index);
  plan->gpu_resources = std::make_unique<RunGpuResources>(plan->run.gpu_memory_budget_bytes);
  clock.Mark("starting the GPU and sizing the run");
  const MeanDescriptor& mean = request.mean.get();
  clock.Mark("waiting for the hashing mean");
  ComposeMatcher(request, mean, callbacks, plan);
  clock.Mark("making the matcher");
  OpenSink(plan);
  clock.Mark("opening the database for writing");
  // Verification on the run's first device, where matching runs too.
  if (!plan->run.options.skip_geometric_verification) {
    plan->verifier =
        CreateBatchVerifierOnDevice(plan->run.options, plan->run.gpu_index, plan->gpu_resources.get());
    clock.Mark("making the verifier");
  }
}

// Takes the plan apart in the order its destructor would, timing each part:
// closing the database (its last checkpoint) and freeing GPU memory are
// waits too, before the command can print its summary.
void DismantlePlan(RunPlan& plan, PhaseClock& clock) {
  plan.verifier.reset();
  clock.Mark("freeing the verifier");
  plan.sink = nullptr;
  plan.sender.reset();
  plan.locked_sink.reset();
  plan.database_sink.reset();
  clock.Mark("closing the database");
  plan.rematch.reset();
  plan.matcher.reset();
  plan.gpu_resources.reset();  // the blocks the owners still cache
  clock.Mark("freeing the matcher");
  plan.features = nullptr;
  plan.cache.reset();
  clock.Mark("stopping the feature reader");
}

// The run's own books of GPU memory against its budget, and every fall
// back to the CPU for want of device memory (rank 0's share).
void ReportGpuMemory(const MatchingSummary& summary, const MatchingCallbacks& callbacks) {
  const RunGpuMemoryBooks& books = summary.gpu_memory;
  if (books.devices == 0) return;
  Info(callbacks, "GPU memory: at most " + FormatMemorySize(books.peak_held_bytes) + " held (" +
                      FormatMemorySize(books.peak_in_use_bytes) + " in use) of " +
                      (books.budget_bytes > 0 ? "--max_gpu_memory " + FormatMemorySize(books.budget_bytes)
                                              : std::string("the device (no --max_gpu_memory)")) +
                      "; " + std::to_string(books.blocks_made) + " blocks allocated, " +
                      std::to_string(books.blocks_reused) + " reused, " + std::to_string(books.blocks_trimmed) +
                      " given back");
  if (summary.gpu_memory_fallbacks > 0) {
    Warn(callbacks, "CPU fallback: " + std::to_string(summary.gpu_memory_fallbacks) +
                        " times a GPU part found no room in GPU memory and went on on the CPU");
  }
}

// What the matcher's wrappers and the feature cache did, for the log.
void ReportMatcherStats(const RunPlan& plan, size_t num_images, const MatchingCallbacks& callbacks) {
  const MatcherCommandOptions& options = plan.run.options;
  if (plan.retaining != nullptr) {
    const RetainingStats& kept = plan.retaining->stats();
    Info(callbacks, "Hashing: " + std::to_string(kept.images_added) + " images hashed, " +
                        std::to_string(kept.images_reused) + " times reused, " +
                        std::to_string(kept.images_dropped) + " dropped to stay within " +
                        FormatMemorySize(plan.keep_bytes));
  }
  if (plan.guided != nullptr) {
    Info(callbacks, DescribeGuidedMatching(plan.guided->stats(), options.guided));
  }
  if (plan.rematch && plan.rematch->counts().rematched > 0) {
    const ExactRematchCounts& counts = plan.rematch->counts();
    std::ostringstream text;
    text << "Exact rematch: " << counts.rematched << " of " << counts.pairs
         << " pairs had " << (options.cashash.exact_rematch_max_matches > 0 ? "" : "at least ")
         << options.cashash.exact_rematch_min_matches;
    if (options.cashash.exact_rematch_max_matches > 0) text << " to " << options.cashash.exact_rematch_max_matches - 1;
    text << " cascade matches and were matched again exactly in " << std::fixed << std::setprecision(3)
         << counts.exact_us * 1e-6 << " s on the " << RematchPlaceName(plan.rematch->policy().where);
    Info(callbacks, text.str());
  }
  if (!plan.cache) return;
  const FeatureCacheStats stats = plan.cache->stats();
  Info(callbacks, "Features: " + std::to_string(stats.source_loads) + " image reads for " +
                      std::to_string(num_images) + " images in " + std::to_string(stats.steps) +
                      " group steps, at most " + FormatMemorySize(stats.peak_bytes) + " cached");
}

// The matcher's name for the log and the summary: with its exact rematch,
// "<backend>+exact-rematch".
std::string RunMatcherName(const RunPlan& plan) {
  return plan.matcher->Name() + (plan.rematch && plan.rematch->policy().enabled() ? "+exact-rematch" : "");
}

// The trace file of this rank: options.pipeline_trace_path, under MPI with
// .rankN appended; empty when no trace is asked for.
std::string PipelineTracePath(const MatcherCommandOptions& options, const RunShare& share) {
  if (options.pipeline_trace_path.empty()) return {};
  std::string path = options.pipeline_trace_path;
  if (share.num_ranks > 1) path += ".rank" + std::to_string(share.rank);
  return path;
}

// A trace is a diagnostic: failing to write it warns, after the run's
// results are committed, instead of failing the run.
void WriteTrace(const PipelineTrace& trace, const std::string& path, const MatchingCallbacks& callbacks) {
  if (path.empty()) return;
  try {
    const size_t events = trace.WriteCsv(path);
    Info(callbacks, "Pipeline trace: " + std::to_string(events) + " stage intervals in " + path);
  } catch (const std::exception& e) {
    Warn(callbacks, e.what());
  }
}

// Runs the pipeline over the plan and reports. Progress counts the pairs of
// every rank written so far; rank 0 merges the other ranks' statistics.
MatchingSummary ExecutePlan(RunPlan& plan, size_t num_images, PhaseClock& clock, const MatchingCallbacks& callbacks) {
  const RunShare& share = plan.share;
  PipelineOptions pipeline_options;
  pipeline_options.num_threads = plan.run.options.sift.num_threads;
  pipeline_options.skip_geometric_verification = plan.run.options.skip_geometric_verification;
  pipeline_options.two_view = plan.run.options.two_view;
  PipelineTrace trace;
  const std::string trace_path = PipelineTracePath(plan.run.options, share);
  if (!trace_path.empty()) pipeline_options.trace = &trace;
  MatchingPipeline pipeline(pipeline_options, plan.features, plan.matcher.get(), plan.sink);

  std::mutex progress_mutex;
  const auto run_start = std::chrono::steady_clock::now();
  auto report_progress = [&](PipelineProgress progress) {
    plan.gpu_memory->Sample();
    if (!callbacks.progress || plan.locked_sink == nullptr) return;
    std::lock_guard<std::mutex> lock(progress_mutex);
    progress.pairs_done = plan.locked_sink->pairs_written();
    progress.pairs_total = share.num_pairs;
    progress.elapsed_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - run_start).count();
    callbacks.progress(progress);
  };
  pipeline.SetProgressCallback(report_progress);
  if (callbacks.stop != nullptr) pipeline.SetStopFlag(callbacks.stop);
  if (plan.verifier) pipeline.SetBatchVerifier(plan.verifier.get());
  if (plan.rematch) pipeline.SetExactRematch(plan.rematch.get());

  MatchingSummary summary;
  summary.matcher_name = RunMatcherName(plan);
  Info(callbacks, "Matcher: " + summary.matcher_name);
  clock.Mark("starting the pipeline");
  if (share.rank > 0) {
    RankReport report;
    report.stats = pipeline.Run(share.my_chunks());
    clock.Restart();
    WriteTrace(trace, trace_path, callbacks);
    report.matcher_name = RunMatcherName(plan);
    MpiResultSender::SendReport(report);
    return MatchingSummary();  // rank 0 reports the run
  }
  if (share.num_ranks == 1) {
    summary.pipeline = pipeline.Run(share.my_chunks());
    clock.Restart();
  } else {
    MpiResultReceiver receiver(plan.sink, [&](const PairChunk& chunk) {
      PipelineProgress progress;
      progress.chunk = &chunk;
      report_progress(progress);
    });
    try {
      summary.pipeline = pipeline.Run(share.my_chunks());
    } catch (const std::exception& e) {
      MpiAbortJob(e.what());  // the other ranks cannot be told otherwise
    }
    for (const RankReport& report : receiver.Join()) MergeStats(report.stats, &summary.pipeline);
    plan.sink->Flush();  // what the receiver wrote after the pipeline's last flush
    clock.Restart();
  }
  WriteTrace(trace, trace_path, callbacks);
  plan.gpu_memory->Sample();
  plan.gpu_memory->Fill(&summary);  // rank 0's device
  summary.gpu_memory = plan.gpu_resources->Books();
  summary.gpu_memory_fallbacks = summary.gpu_memory.matcher_fallbacks +
                                 (plan.rematch ? plan.rematch->counts().held_without_memory.load() : 0) +
                                 (plan.verifier ? plan.verifier->CallsWithoutDeviceMemory() : 0);
  ReportGpuMemory(summary, callbacks);
  ReportMatcherStats(plan, num_images, callbacks);  // rank 0's share
  if (share.num_ranks > 1) {
    Info(callbacks, "Matched by " + std::to_string(share.num_ranks) + " MPI processes");
  } else if (plan.verifier != nullptr && !plan.verifier->StatsSummary().empty()) {
    Info(callbacks, plan.verifier->StatsSummary());
  }
  return summary;
}

}  // namespace

MatchingSummary MatchChunks(RunRequest request, const MatchingCallbacks& callbacks) {
  RunShare share = ShareOfRun(request, callbacks);
  MatchingSummary summary;
  summary.pairs_requested = request.num_pairs_requested;
  summary.pairs_skipped = share.pairs_skipped;
  if (share.num_pairs == 0) {
    Info(callbacks, "Nothing to match.");
    return summary;
  }
  request.clock.Mark("finding the pairs left to match");
  RunPlan plan(request.run);
  PlanRun(request, std::move(share), callbacks, &plan);
  MatchingSummary result = ExecutePlan(plan, request.image_ids.size(), request.clock, callbacks);
  DismantlePlan(plan, request.clock);
  if (plan.share.rank > 0) return result;
  result.pairs_requested = summary.pairs_requested;
  result.pairs_skipped = summary.pairs_skipped;
  result.phases_outside_pipeline = request.clock.phases();
  result.run = request.run;
  return result;
}

}  // namespace colmap
}  // namespace cashash
