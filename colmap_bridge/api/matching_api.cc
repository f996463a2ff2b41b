#include "colmap_bridge/api/matching_api.h"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <future>
#include <iomanip>
#include <iostream>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

#include "cashash/matchers/auto_feature_matcher.h"
#include "cashash/matchers/exact_rematch_feature_matcher.h"
#include "cashash/matchers/fallback_feature_matcher.h"
#include "cashash/pipeline/feature_cache.h"
#include "cashash/matching/guided_matching.h"
#include "cashash/pipeline/pair_generation.h"
#include "cashash/base/pair_id.h"
#include "cashash/matchers/retaining_feature_matcher.h"
#include "cashash/matchers/split_feature_matcher.h"
#include "cashash/pipeline/schedule_sizing.h"
#include "cashash/matching/table_shape.h"
#include "colmap_bridge/completed_pairs.h"
#include "colmap_bridge/database.h"
#include "colmap_bridge/database_pipeline_io.h"
#include "colmap_bridge/api/gpu_memory_query.h"
#include "distributed/mpi_distributed.h"
#include "distributed/mpi_world.h"
#include "colmap_bridge/pair_list.h"
#include "colmap_bridge/api/verifier_selection.h"
#ifdef CASHASH_WITH_CUDA
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#endif

namespace cashash {
namespace colmap {

using distributed::ChunkListChecksum;
using distributed::ChunksOfRank;
using distributed::LockedSink;
using distributed::MpiAbortJob;
using distributed::MpiBarrier;
using distributed::MpiLocalRank;
using distributed::MpiMax;
using distributed::MpiMin;
using distributed::MpiRank;
using distributed::MpiResultReceiver;
using distributed::MpiResultSender;
using distributed::MpiSize;
using distributed::RankReport;

namespace {

// The hashing mean comes from at most this many images spread evenly over
// the database, so that a huge database is not read twice for it.
constexpr size_t kMaxImagesForMean = 100;

MeanDescriptor ComputeDatabaseMean(const Database& database, const std::vector<image_t>& image_ids) {
  std::vector<FeatureDescriptors> sample;
  const size_t n = image_ids.size();
  const size_t count = std::min(n, kMaxImagesForMean);
  for (size_t k = 0; k < count; ++k) {
    sample.push_back(database.ReadDescriptors(image_ids[k * n / count]));
  }
  std::vector<const FeatureDescriptors*> pointers;
  for (const FeatureDescriptors& d : sample) pointers.push_back(&d);
  return ComputeMeanDescriptor(pointers);
}

// The mean on a thread of its own, through a read-only connection of its
// own, started before the GPU is: reading its 100 images (about 0.14 s for
// 8,192 features each) then overlaps starting the device and sizing the run,
// which the user otherwise waits for one after the other.
std::shared_future<MeanDescriptor> StartDatabaseMean(DatabaseFeatureSource& source,
                                                     std::vector<image_t> image_ids) {
  return std::async(std::launch::async, [path = source.database().path(), ids = std::move(image_ids)]() {
           const Database database(path, /*read_only=*/true);
           return ComputeDatabaseMean(database, ids);
         })
      .share();
}

#ifdef CASHASH_WITH_CUDA
// The devices of --FeatureMatching.gpu_index: "-1" (the first), "2", or a
// comma-separated list "0,1" (one matcher per device, SplitFeatureMatcher).
std::vector<int> GpuIndices(const std::string& gpu_index) {
  std::vector<int> indices;
  size_t at = 0;
  while (at <= gpu_index.size()) {
    const size_t comma = std::min(gpu_index.find(',', at), gpu_index.size());
    const std::string item = gpu_index.substr(at, comma - at);
    size_t used = 0;
    int value = -1;
    try {
      value = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (item.empty() || used != item.size()) {
      throw std::invalid_argument("--FeatureMatching.gpu_index: expected an integer or a comma-separated list, got '" +
                                  gpu_index + "'");
    }
    value = std::max(0, value);
    if (std::find(indices.begin(), indices.end(), value) == indices.end()) indices.push_back(value);
    at = comma + 1;
  }
  return indices;
}

int FirstGpuIndex(const std::string& gpu_index) { return GpuIndices(gpu_index).front(); }
#endif

// Callers that set no warning sink still see warnings, on stderr as the
// command line prints them.
void Warn(const MatchingCallbacks& callbacks, const std::string& text) {
  if (callbacks.warning) {
    callbacks.warning(text);
  } else {
    std::cerr << "WARNING: " << text << std::endl;
  }
}

void Info(const MatchingCallbacks& callbacks, const std::string& text) {
  if (callbacks.info) callbacks.info(text);
}

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

// The options as the command line would run them on `database_path`;
// throws std::invalid_argument with the command line's message when one is
// out of range.
MatcherCommandOptions CheckedOptions(const std::string& database_path, const MatcherCommandOptions& options) {
  MatcherCommandOptions checked = options;
  checked.database_path = database_path;
  const std::string problem = CheckMatcherCommandOptions(checked);
  if (!problem.empty()) throw std::invalid_argument(problem);
  return checked;
}

std::vector<image_t> ImageIds(const DatabaseFeatureSource& source) {
  std::vector<image_t> ids;
  for (const Image& image : source.images()) ids.push_back(image.image_id);
  return ids;
}

std::vector<image_t> ImagesOfPairs(const std::vector<ImagePair>& pairs) {
  std::vector<image_t> image_ids;
  for (const ImagePair& pair : pairs) {
    image_ids.push_back(pair.first);
    image_ids.push_back(pair.second);
  }
  std::sort(image_ids.begin(), image_ids.end());
  image_ids.erase(std::unique(image_ids.begin(), image_ids.end()), image_ids.end());
  return image_ids;
}

// Feature rows of each image (row counts only, no descriptors are read).
std::vector<size_t> RowsOfImages(DatabaseFeatureSource& source, const std::vector<image_t>& image_ids) {
  std::vector<size_t> rows;
  rows.reserve(image_ids.size());
  for (image_t image_id : image_ids) rows.push_back(source.database().NumDescriptors(image_id));
  return rows;
}

// Adds the statistics of another rank's pipeline to rank 0's: counts add
// up, times are the longest rank's.
void MergeStats(const PipelineStats& other, PipelineStats* stats) {
  stats->pairs_total += other.pairs_total;
  stats->pairs_done += other.pairs_done;
  stats->raw_matches += other.raw_matches;
  stats->verified_pairs += other.verified_pairs;
  stats->inlier_matches += other.inlier_matches;
  stats->seconds_total = std::max(stats->seconds_total, other.seconds_total);
  stats->seconds_loading = std::max(stats->seconds_loading, other.seconds_loading);
  stats->seconds_hashing = std::max(stats->seconds_hashing, other.seconds_hashing);
  stats->seconds_matching = std::max(stats->seconds_matching, other.seconds_matching);
  stats->seconds_verification = std::max(stats->seconds_verification, other.seconds_verification);
  stats->seconds_writing = std::max(stats->seconds_writing, other.seconds_writing);
  stats->seconds_matching_wait_queue = std::max(stats->seconds_matching_wait_queue, other.seconds_matching_wait_queue);
  stats->seconds_verification_wait_input =
      std::max(stats->seconds_verification_wait_input, other.seconds_verification_wait_input);
  stats->seconds_verification_wait_writer =
      std::max(stats->seconds_verification_wait_writer, other.seconds_verification_wait_writer);
  stats->seconds_writing_wait_input = std::max(stats->seconds_writing_wait_input, other.seconds_writing_wait_input);
  stats->stopped = stats->stopped || other.stopped;
}

// Device memory in use on the run's GPU: before the matcher exists, then
// after every committed block (the writer thread, and the MPI receiver's).
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

int GpuIndexForRun(const MatcherCommandOptions& options);

// Runs the pipeline over `chunks`, leaving out pairs already in the database
// unless options.overwrite is set. With `cache_groups` (chunks of
// ScheduledPairChunks) features are read through a GroupFeatureCache: one
// group pair in host memory, the next one loaded meanwhile.
//
// Under MPI every rank computes the same chunk list (the database is read
// by all, read-only, before rank 0 opens it for writing) and matches its
// share (ChunksOfRank); rank 0 writes everything (mpi_distributed.h).
//
// With matcher_keep_bytes > 0 the matcher keeps released images up to that
// many bytes (RetainingFeatureMatcher), so that most images are hashed once.
MatchingSummary MatchChunks(const MatcherCommandOptions& options, DatabaseFeatureSource& source,
                            const std::vector<image_t>& image_ids, std::vector<PairChunk> chunks,
                            size_t num_pairs_requested, bool cache_groups, size_t matcher_keep_bytes,
                            std::shared_future<MeanDescriptor> mean_of_database, const MatchingCallbacks& callbacks) {
  const int rank = MpiRank(), num_ranks = MpiSize();
  MatchingSummary summary;
  summary.pairs_requested = num_pairs_requested;
  if (!options.overwrite) {
    // One bit per pair of the run, whatever the database holds.
    const CompletedPairs done = ReadCompletedPairs(source.database(), image_ids, chunks);
    if (done.num_completed() > 0) {
      chunks = RemovePairs(std::move(chunks),
                           [&](const ImagePair& pair) { return done.Contains(pair.first, pair.second); });
    }
  }
  if (num_ranks > 1) {
    const uint64_t checksum = ChunkListChecksum(chunks);
    if (MpiMin(checksum) != MpiMax(checksum)) {
      throw std::runtime_error("MPI ranks disagree on the pairs to match (same database and options on every rank?)");
    }
    // Every rank has read the completed pairs: rank 0 may start writing.
    MpiBarrier();
  }
  size_t num_pairs = 0;
  for (const PairChunk& chunk : chunks) num_pairs += chunk.pairs.size();
  summary.pairs_skipped = num_pairs_requested - num_pairs;
  if (summary.pairs_skipped > 0) {
    Info(callbacks, "Skipping " + std::to_string(summary.pairs_skipped) + " of " +
                        std::to_string(num_pairs_requested) +
                        " pairs already in the database (use --overwrite 1 to match them again)");
  }
  if (num_pairs == 0) {
    Info(callbacks, "Nothing to match.");
    return summary;
  }
  if (rank == 0) WarnAboutSmallImages(source, image_ids, callbacks);
  const std::vector<PairChunk> my_chunks = num_ranks > 1 ? ChunksOfRank(chunks, rank, num_ranks) : chunks;
  // The cache's loading thread reads `source` from here on (this thread no
  // longer does), so it is made before the GPU, the matcher and the verifier:
  // the first chunk's features are read while they start, instead of after
  // (device run 27: the matching thread's first wait for features was
  // 0.05-0.14 s at 300 images, and the setup 0.3 s).
  std::unique_ptr<GroupFeatureCache> cache;
  if (cache_groups) cache = std::make_unique<GroupFeatureCache>(&source, my_chunks);

  MatcherCommandOptions run_options = options;
#ifdef CASHASH_WITH_CUDA
  // Ranks sharing a machine share its GPUs unless a device is named.
  if (num_ranks > 1 && options.gpu_index == "-1") {
    const int devices = cuda::NumCudaDevices();
    if (devices > 1) run_options.gpu_index = std::to_string(MpiLocalRank() % devices);
  }
#endif
  GpuMemorySampler gpu_memory(GpuIndexForRun(run_options));
  const MeanDescriptor mean = mean_of_database.get();
  const auto rematch_counts = std::make_shared<ExactRematchCounts>();
  std::unique_ptr<FeatureMatcher> matcher =
      CreateMatcherForOptions(run_options, mean, [&](const std::string& text) { Warn(callbacks, text); },
                              [&](const std::string& text) { Info(callbacks, text); }, rematch_counts);
  // Guided matching (Ga-CasHash, cashash/guided_matching.h): a second
  // matcher for the top-scale subsets, the stage-1 F estimator, and the
  // pipeline's features read through a source that keeps the keypoints.
  std::unique_ptr<KeypointRecordingSource> keypoint_source;
  GuidedFeatureMatcher* guided = nullptr;
  if (options.guided.enabled) {
    keypoint_source = std::make_unique<KeypointRecordingSource>(nullptr);
    auto guided_matcher = std::make_unique<GuidedFeatureMatcher>(
        std::move(matcher), CreateMatcherForOptions(run_options, mean, nullptr),
        CreateFundamentalEstimatorForOptions(run_options), keypoint_source.get(), options.guided,
        options.sift.max_num_matches, options.two_view.random_seed, options.sift.num_threads);
    guided = guided_matcher.get();
    matcher = std::move(guided_matcher);
  }
  RetainingFeatureMatcher* retaining = nullptr;
  if (matcher_keep_bytes > 0) {
    const size_t max_rows = static_cast<size_t>(std::max(1, options.sift.max_num_matches));
    // A guided matcher also holds the top-scale subset and the positions.
    const double share = options.guided.enabled ? 1.0 + options.guided.top_scale_fraction : 1.0;
    const size_t position_bytes = options.guided.enabled ? 24 : 0;
    auto keeping = std::make_unique<RetainingFeatureMatcher>(
        std::move(matcher), matcher_keep_bytes, [max_rows, tables = options.cashash.num_tables, share,
                                                 position_bytes](const FeatureDescriptors& d) {
          const size_t rows = std::min(d.rows(), max_rows);
          return static_cast<size_t>(share * static_cast<double>(MatcherBytesPerImage(rows, tables))) +
                 rows * position_bytes;
        });
    retaining = keeping.get();
    matcher = std::move(keeping);
  }

  // Rank 0 alone opens the database for writing (and takes the writer
  // lock); the other ranks send their results to it.
  std::unique_ptr<DatabaseResultSink> database_sink;
  std::unique_ptr<LockedSink> locked_sink;
  std::unique_ptr<MpiResultSender> sender;
  ResultSink* sink = nullptr;
  if (rank == 0) {
    database_sink = std::make_unique<DatabaseResultSink>(
        options.database_path, DatabaseResultSink::Options{!options.skip_geometric_verification,
                                                           options.write_empty_pairs, options.overwrite});
    locked_sink = std::make_unique<LockedSink>(database_sink.get());
    sink = locked_sink.get();
  } else {
    sender = std::make_unique<MpiResultSender>(my_chunks);
    sink = sender.get();
  }

  PipelineOptions pipeline_options;
  pipeline_options.num_threads = options.sift.num_threads;
  pipeline_options.skip_geometric_verification = options.skip_geometric_verification;
  pipeline_options.two_view = options.two_view;
  FeatureSource* features = cache ? static_cast<FeatureSource*>(cache.get()) : &source;
  if (keypoint_source) {
    keypoint_source->SetInner(features);
    features = keypoint_source.get();
  }
  MatchingPipeline pipeline(pipeline_options, features, matcher.get(), sink);

  // Progress counts the pairs of every rank written so far.
  std::mutex progress_mutex;
  const auto run_start = std::chrono::steady_clock::now();
  auto report_progress = [&](PipelineProgress progress) {
    gpu_memory.Sample();
    if (!callbacks.progress || locked_sink == nullptr) return;
    std::lock_guard<std::mutex> lock(progress_mutex);
    progress.pairs_done = locked_sink->pairs_written();
    progress.pairs_total = num_pairs;
    progress.elapsed_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - run_start).count();
    callbacks.progress(progress);
  };
  pipeline.SetProgressCallback(report_progress);
  if (callbacks.stop != nullptr) pipeline.SetStopFlag(callbacks.stop);
  // Verification on the GPU too when use_gpu is set (the matcher has
  // already warned when no GPU can be used).
  std::unique_ptr<BatchVerifier> verifier;
  if (!options.skip_geometric_verification) {
    verifier = CreateBatchVerifierForOptions(run_options, nullptr);
    pipeline.SetBatchVerifier(verifier.get());
  }
  summary.matcher_name = matcher->Name();
  Info(callbacks, "Matcher: " + summary.matcher_name);
  // How well the group level worked: database reads against images.
  auto report_cache = [&]() {
    if (retaining != nullptr) {
      const RetainingStats& kept = retaining->stats();
      Info(callbacks, "Hashing: " + std::to_string(kept.images_added) + " images hashed, " +
                          std::to_string(kept.images_reused) + " times reused, " +
                          std::to_string(kept.images_dropped) + " dropped to stay within " +
                          FormatMemorySize(matcher_keep_bytes));
    }
    if (guided != nullptr) {
      Info(callbacks, DescribeGuidedMatching(guided->stats(), options.guided));
    }
    if (rematch_counts->rematched > 0) {
      std::ostringstream text;
      text << "Exact rematch: " << rematch_counts->rematched << " of " << rematch_counts->pairs
           << " pairs had at least " << options.cashash.exact_rematch_min_matches
           << " cascade matches and were matched again exactly in " << std::fixed << std::setprecision(3)
           << rematch_counts->exact_us * 1e-6 << " s";
      Info(callbacks, text.str());
    }
    if (!cache) return;
    const FeatureCacheStats stats = cache->stats();
    Info(callbacks, "Features: " + std::to_string(stats.source_loads) + " image reads for " +
                        std::to_string(image_ids.size()) + " images in " + std::to_string(stats.steps) +
                        " group steps, at most " + FormatMemorySize(stats.peak_bytes) + " cached");
  };
  if (num_ranks == 1) {
    summary.pipeline = pipeline.Run(my_chunks);
    // The GPU matcher may have handed over to the CPU on running out of memory.
    summary.matcher_name = matcher->Name();
    gpu_memory.Sample();
    gpu_memory.Fill(&summary);
    report_cache();
    if (verifier != nullptr && !verifier->StatsSummary().empty()) Info(callbacks, verifier->StatsSummary());
    return summary;
  }

  if (rank > 0) {
    RankReport report;
    report.stats = pipeline.Run(my_chunks);
    report.matcher_name = matcher->Name();
    MpiResultSender::SendReport(report);
    return MatchingSummary();  // rank 0 reports the run
  }
  MpiResultReceiver receiver(sink, [&](const PairChunk& chunk) {
    PipelineProgress progress;
    progress.chunk = &chunk;
    report_progress(progress);
  });
  try {
    summary.pipeline = pipeline.Run(my_chunks);
  } catch (const std::exception& e) {
    MpiAbortJob(e.what());  // the other ranks cannot be told otherwise
  }
  for (const RankReport& report : receiver.Join()) MergeStats(report.stats, &summary.pipeline);
  summary.matcher_name = matcher->Name();
  gpu_memory.Sample();
  gpu_memory.Fill(&summary);  // rank 0's device
  report_cache();  // rank 0's share
  Info(callbacks, "Matched by " + std::to_string(num_ranks) + " MPI processes");
  return summary;
}

// The device the matcher will run on, or -1 for the CPU.
int GpuIndexForRun(const MatcherCommandOptions& options) {
#ifdef CASHASH_WITH_CUDA
  if (!options.use_gpu) return -1;
  const int gpu_index = FirstGpuIndex(options.gpu_index);
  std::string reason;
  return cuda::CudaDeviceUsable(gpu_index, &reason) ? gpu_index : -1;
#else
  (void)options;
  return -1;
#endif
}

// Block and group sizes for the three-level scheduling from the memory caps
// (options or defaults) and the images' feature counts (row counts only, no
// descriptors are read). A --max_gpu_memory also caps the GPU matcher
// (CASHASH_GPU_MEMORY_LIMIT_MB, unless that is set already).
ScheduleSizes ChooseSizesForRun(const MatcherCommandOptions& options, DatabaseFeatureSource& source,
                                const std::vector<image_t>& image_ids, const MatchingCallbacks& callbacks) {
  ScheduleLimits limits;
  if (options.max_host_memory.empty()) {
    const size_t physical = PhysicalMemoryBytes();
    limits.max_host_bytes = physical > 0 ? physical / 2 : (size_t{8} << 30);
  } else {
    ParseMemorySize(options.max_host_memory, &limits.max_host_bytes);  // checked with the options
  }
  const int gpu_index = GpuIndexForRun(options);
  if (gpu_index >= 0) {
    if (options.max_gpu_memory.empty()) {
      limits.max_gpu_bytes = GpuFreeMemoryBytes(gpu_index);
    } else {
      ParseMemorySize(options.max_gpu_memory, &limits.max_gpu_bytes);
      if (std::getenv("CASHASH_GPU_MEMORY_LIMIT_MB") == nullptr) {
        setenv("CASHASH_GPU_MEMORY_LIMIT_MB", std::to_string(limits.max_gpu_bytes >> 20).c_str(), 1);
      }
    }
  }
  // Ranks must cut the same blocks and groups: the smallest caps of all.
  limits.max_host_bytes = MpiMin(limits.max_host_bytes);
  limits.max_gpu_bytes = MpiMin(limits.max_gpu_bytes);
  limits.block_size = options.block_size_from_memory ? 0 : options.block_size;
  limits.max_num_matches = options.sift.max_num_matches;
  limits.num_tables = options.cashash.num_tables;
  std::vector<size_t> features;
  for (image_t image_id : image_ids) features.push_back(source.database().NumDescriptors(image_id));
  ScheduleSizes sizes = ChooseScheduleSizes(features, limits);
  if (options.block_size_from_memory) sizes.block_size = std::min(sizes.block_size, options.block_size);
  if (!sizes.warning.empty()) Warn(callbacks, sizes.warning);
  const size_t num_blocks = (image_ids.size() + sizes.block_size - 1) / sizes.block_size;
  const size_t num_groups = (num_blocks + sizes.blocks_per_group - 1) / sizes.blocks_per_group;
  Info(callbacks, "Schedule: blocks of " + std::to_string(sizes.block_size) + " images, groups of " +
                      std::to_string(sizes.blocks_per_group) + " blocks (" + std::to_string(num_blocks) +
                      " blocks, " + std::to_string(num_groups) + " groups); host memory " +
                      FormatMemorySize(sizes.predicted_host_bytes) + " of " +
                      FormatMemorySize(limits.max_host_bytes) +
                      (limits.max_gpu_bytes > 0 ? ", GPU memory for images " +
                                                      FormatMemorySize(sizes.predicted_gpu_bytes) + " of " +
                                                      FormatMemorySize(limits.max_gpu_bytes)
                                                : std::string()));
  return sizes;
}

// Pairs of image ids for pairs of names, checked as a pair list file is:
// unknown names and self-pairs are errors, repeats are matched once.
std::vector<ImagePair> PairsOfNames(const std::vector<std::pair<std::string, std::string>>& name_pairs,
                                    const DatabaseFeatureSource& source) {
  std::unordered_map<std::string, image_t> ids_by_name;
  for (const Image& image : source.images()) ids_by_name.emplace(image.name, image.image_id);
  std::vector<ImagePair> pairs;
  std::unordered_set<pair_t> seen;
  for (size_t i = 0; i < name_pairs.size(); ++i) {
    const std::string where = "image pair " + std::to_string(i);
    const std::string& name1 = name_pairs[i].first;
    const std::string& name2 = name_pairs[i].second;
    const auto it1 = ids_by_name.find(name1);
    if (it1 == ids_by_name.end()) throw std::runtime_error(where + ": image '" + name1 + "' is not in table images");
    const auto it2 = ids_by_name.find(name2);
    if (it2 == ids_by_name.end()) throw std::runtime_error(where + ": image '" + name2 + "' is not in table images");
    if (it1->second == it2->second) throw std::runtime_error(where + ": pair of image '" + name1 + "' with itself");
    if (seen.insert(ImagePairToPairId(it1->second, it2->second)).second) {
      pairs.emplace_back(it1->second, it2->second);
    }
  }
  return pairs;
}

MatchingSummary MatchIdPairs(const MatcherCommandOptions& options, DatabaseFeatureSource& source,
                             const std::vector<ImagePair>& pairs, const MatchingCallbacks& callbacks) {
  const size_t block = static_cast<size_t>(options.block_size);
  std::vector<PairChunk> chunks = ListPairChunks(pairs, block * block, 2 * block);
  const std::vector<image_t> image_ids = ImagesOfPairs(pairs);
  std::shared_future<MeanDescriptor> mean = StartDatabaseMean(source, image_ids);
  const MatcherCommandOptions resolved = ResolveOptionsForRun(
      options, RowsOfImages(source, image_ids), [&](const std::string& text) { Info(callbacks, text); });
  return MatchChunks(resolved, source, image_ids, std::move(chunks), pairs.size(), /*cache_groups=*/false,
                     /*matcher_keep_bytes=*/0, std::move(mean), callbacks);
}

}  // namespace

namespace {

// The backend of one matcher type (cascade or brute force): on the GPUs of
// the options where usable, else on the CPU. *on_gpu says which.
std::unique_ptr<FeatureMatcher> CreateBackendForOptions(const MatcherCommandOptions& options,
                                                        const MeanDescriptor& mean,
                                                        const std::function<void(const std::string&)>& warning,
                                                        bool* on_gpu) {
  *on_gpu = false;
  if (options.use_gpu) {
#ifdef CASHASH_WITH_CUDA
    std::vector<std::unique_ptr<FeatureMatcher>> parts;
    std::string reason;
    for (const int gpu_index : GpuIndices(options.gpu_index)) {
      std::string why;
      if (!cuda::CudaDeviceUsable(gpu_index, &why)) {
        reason += (reason.empty() ? "" : "; ") + std::string("device ") + std::to_string(gpu_index) + ": " + why;
        continue;
      }
      // A run that outgrows the card (device memory) finishes on the CPU.
      parts.push_back(CreateFallbackFeatureMatcher(
          cuda::CreateGpuFeatureMatcher(options.sift, options.cashash, mean, gpu_index),
          [sift = options.sift, cashash = options.cashash, mean]() {
            return CreateCpuFeatureMatcher(sift, cashash, mean);
          },
          IsDeviceMemoryError, warning));
    }
    if (!parts.empty()) {
      *on_gpu = true;
      if (!reason.empty() && warning) warning("not every listed GPU is usable (" + reason + "); matching on the others");
      if (parts.size() == 1) return std::move(parts[0]);
      // Several devices share every chunk of pairs.
      return std::make_unique<SplitFeatureMatcher>(std::move(parts));
    }
    if (warning) warning("no usable CUDA device (" + reason + "); matching on the CPU");
#else
    if (warning) warning("cashash was built without CUDA; matching on the CPU");
#endif
  }
  return CreateCpuFeatureMatcher(options.sift, options.cashash, mean);
}

}  // namespace

// The cascade backend of a run; with --CasHash.exact_rematch_min_matches > 0
// it also matches the pairs that may verify again exactly, from the
// descriptors it holds (exact_rematch_feature_matcher.h). Guided matching
// keeps the bare cascade: its stage 2 screens by the epipolar band.
std::unique_ptr<FeatureMatcher> CreateCascadeForOptions(const MatcherCommandOptions& options,
                                                        const MeanDescriptor& mean,
                                                        const std::function<void(const std::string&)>& warning,
                                                        const std::shared_ptr<ExactRematchCounts>& counts,
                                                        bool* on_gpu) {
  MatcherCommandOptions cascade = options;
  cascade.cashash.matcher = MatcherType::kCascade;
  std::unique_ptr<FeatureMatcher> matcher = CreateBackendForOptions(cascade, mean, warning, on_gpu);
  if (options.guided.enabled || options.cashash.exact_rematch_min_matches <= 0) return matcher;
  return std::make_unique<ExactRematchFeatureMatcher>(
      std::move(matcher), static_cast<size_t>(options.cashash.exact_rematch_min_matches), counts);
}

std::unique_ptr<FeatureMatcher> CreateMatcherForOptions(const MatcherCommandOptions& options,
                                                        const MeanDescriptor& mean,
                                                        const std::function<void(const std::string&)>& warning,
                                                        const std::function<void(const std::string&)>& info,
                                                        const std::shared_ptr<ExactRematchCounts>& counts) {
  bool on_gpu = false;
  if (options.cashash.matcher == MatcherType::kCascade) {
    return CreateCascadeForOptions(options, mean, warning, counts, &on_gpu);
  }
  if (options.cashash.matcher != MatcherType::kAuto) return CreateBackendForOptions(options, mean, warning, &on_gpu);
  // Guided matching filters candidates inside the cascade.
  if (options.guided.enabled) return CreateCascadeForOptions(options, mean, warning, counts, &on_gpu);
  MatcherCommandOptions brute_force = options;
  brute_force.cashash.matcher = MatcherType::kBruteForce;
  // Both on the same devices (or both on the CPU); the warnings once.
  std::unique_ptr<FeatureMatcher> cascade_matcher = CreateCascadeForOptions(options, mean, warning, counts, &on_gpu);
  bool brute_force_on_gpu = false;
  std::unique_ptr<FeatureMatcher> brute_force_matcher =
      CreateBackendForOptions(brute_force, mean, nullptr, &brute_force_on_gpu);
  return std::make_unique<AutoFeatureMatcher>(std::move(cascade_matcher), std::move(brute_force_matcher),
                                              on_gpu ? GpuAutoMatcherOptions() : CpuAutoMatcherOptions(options.sift),
                                              info);
}

MatcherCommandOptions ResolveOptionsForRun(const MatcherCommandOptions& options,
                                           const std::vector<size_t>& rows_per_image,
                                           const std::function<void(const std::string&)>& info) {
  MatcherCommandOptions resolved = options;
  if (resolved.guided.enabled && resolved.cashash.matcher == MatcherType::kAuto) {
    resolved.cashash.matcher = MatcherType::kCascade;
    if (info) info("Matcher: cascade (guided matching needs it)");
  }
  const size_t features = TypicalFeatureCount(rows_per_image, options.sift.max_num_matches);
  resolved.cashash = ResolveTableShape(resolved.cashash, features);
  if (info && resolved.cashash.matcher != MatcherType::kBruteForce) {
    info(DescribeTableShape(options.cashash, resolved.cashash, features, rows_per_image.size()));
  }
  return resolved;
}

namespace {

// What ranks > 0 tell the user: warnings only, marked with their rank; rank
// 0 reports the run.
MatchingCallbacks CallbacksOfRank(const MatchingCallbacks& callbacks) {
  if (MpiRank() == 0) return callbacks;
  MatchingCallbacks quiet;
  quiet.stop = callbacks.stop;
  quiet.warning = [rank = MpiRank()](const std::string& text) {
    std::cerr << "WARNING: [rank " << rank << "] " << text << std::endl;
  };
  return quiet;
}

// Under MPI an error on one rank must end them all: the others would wait
// for it in a collective or a receive forever.
template <typename Body>
MatchingSummary EndAllRanksOnError(Body body) {
  if (MpiSize() == 1) return body();
  try {
    return body();
  } catch (const std::exception& e) {
    MpiAbortJob(e.what());
  }
}

}  // namespace

MatchingSummary MatchExhaustive(const std::string& database_path, const MatcherCommandOptions& options,
                                const MatchingCallbacks& all_callbacks) {
  return EndAllRanksOnError([&]() {
    const MatchingCallbacks callbacks = CallbacksOfRank(all_callbacks);
    const MatcherCommandOptions checked = CheckedOptions(database_path, options);
    DatabaseFeatureSource source(database_path);
    if (callbacks.database_opened) callbacks.database_opened();
    const std::vector<image_t> image_ids = ImageIds(source);
    if (image_ids.size() < 2) {
      Warn(callbacks, "table images of " + database_path + " holds " + std::to_string(image_ids.size()) + " image" +
                          (image_ids.size() == 1 ? "" : "s") + "; nothing to match");
      return MatchingSummary();
    }
    std::shared_future<MeanDescriptor> mean = StartDatabaseMean(source, image_ids);
    const MatcherCommandOptions resolved = ResolveOptionsForRun(
        checked, RowsOfImages(source, image_ids), [&](const std::string& text) { Info(callbacks, text); });
    const ScheduleSizes sizes = ChooseSizesForRun(resolved, source, image_ids, callbacks);
    std::vector<PairChunk> chunks = ScheduledPairChunks(image_ids, sizes.block_size, sizes.blocks_per_group);
    const size_t n = image_ids.size();
    return MatchChunks(resolved, source, image_ids, std::move(chunks), n * (n - 1) / 2, /*cache_groups=*/true,
                       sizes.matcher_keep_bytes, std::move(mean), callbacks);
  });
}

MatchingSummary MatchPairs(const std::string& database_path,
                           const std::vector<std::pair<std::string, std::string>>& image_name_pairs,
                           const MatcherCommandOptions& options, const MatchingCallbacks& all_callbacks) {
  return EndAllRanksOnError([&]() {
    const MatchingCallbacks callbacks = CallbacksOfRank(all_callbacks);
    const MatcherCommandOptions checked = CheckedOptions(database_path, options);
    DatabaseFeatureSource source(database_path);
    if (callbacks.database_opened) callbacks.database_opened();
    return MatchIdPairs(checked, source, PairsOfNames(image_name_pairs, source), callbacks);
  });
}

MatchingSummary MatchPairList(const std::string& database_path, const std::string& match_list_path,
                              const MatcherCommandOptions& options, const MatchingCallbacks& all_callbacks) {
  return EndAllRanksOnError([&]() {
    const MatchingCallbacks callbacks = CallbacksOfRank(all_callbacks);
    const MatcherCommandOptions checked = CheckedOptions(database_path, options);
    DatabaseFeatureSource source(database_path);
    if (callbacks.database_opened) callbacks.database_opened();
    std::unordered_map<std::string, image_t> ids_by_name;
    for (const Image& image : source.images()) ids_by_name.emplace(image.name, image.image_id);
    std::ifstream file(match_list_path);
    if (!file) throw std::runtime_error("cannot open --match_list_path " + match_list_path);
    return MatchIdPairs(checked, source, ParsePairList(file, match_list_path, ids_by_name), callbacks);
  });
}

}  // namespace colmap
}  // namespace cashash
