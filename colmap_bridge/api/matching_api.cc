#include "colmap_bridge/api/matching_api.h"

#include <algorithm>
#include <fstream>
#include <future>
#include <iostream>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

#include "cashash/base/pair_id.h"
#include "cashash/pipeline/pair_generation.h"
#include "cashash/pipeline/schedule_sizing.h"
#include "colmap_bridge/api/gpu_memory_query.h"
#include "colmap_bridge/api/matcher_factory.h"
#include "colmap_bridge/api/run_plan.h"
#include "colmap_bridge/database.h"
#include "colmap_bridge/database_pipeline_io.h"
#include "colmap_bridge/pair_list.h"
#include "distributed/mpi_world.h"

namespace cashash {
namespace colmap {

using distributed::MpiAbortJob;
using distributed::MpiMin;
using distributed::MpiRank;
using distributed::MpiSize;

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

// Feature rows of each image (row counts only, no descriptors are read).
std::vector<size_t> RowsOfImages(DatabaseFeatureSource& source, const std::vector<image_t>& image_ids) {
  std::vector<size_t> rows;
  rows.reserve(image_ids.size());
  for (image_t image_id : image_ids) rows.push_back(source.database().NumDescriptors(image_id));
  return rows;
}

// Block and group sizes for the three-level scheduling from the memory caps
// (options or defaults) and the images' feature counts (row counts only, no
// descriptors are read).
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
      ParseMemorySize(options.max_gpu_memory, &limits.max_gpu_bytes);  // checked with the options
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
                             const std::vector<ImagePair>& pairs, const PhaseClock& clock,
                             const MatchingCallbacks& callbacks) {
  const size_t block = static_cast<size_t>(options.block_size);
  std::vector<PairChunk> chunks = ListPairChunks(pairs, block * block, 2 * block);
  const std::vector<image_t> image_ids = ImagesOfPairs(pairs);
  std::shared_future<MeanDescriptor> mean = StartDatabaseMean(source, image_ids);
  const MatcherCommandOptions resolved = ResolveOptionsForRun(
      options, RowsOfImages(source, image_ids), [&](const std::string& text) { Info(callbacks, text); });
  RunRequest request;
  request.options = resolved;
  request.source = &source;
  request.image_ids = image_ids;
  request.chunks = std::move(chunks);
  request.num_pairs_requested = pairs.size();
  request.mean = std::move(mean);
  request.clock = clock;
  request.clock.Mark("reading the pairs and feature counts");
  return MatchChunks(std::move(request), callbacks);
}

}  // namespace

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
    PhaseClock clock;
    const MatchingCallbacks callbacks = CallbacksOfRank(all_callbacks);
    const MatcherCommandOptions checked = CheckedOptions(database_path, options);
    DatabaseFeatureSource source(database_path);
    if (callbacks.database_opened) callbacks.database_opened();
    clock.Mark("opening the database");
    const std::vector<image_t> image_ids = ImageIds(source);
    if (image_ids.size() < 2) {
      Warn(callbacks, "table images of " + database_path + " holds " + std::to_string(image_ids.size()) + " image" +
                          (image_ids.size() == 1 ? "" : "s") + "; nothing to match");
      return MatchingSummary();
    }
    std::shared_future<MeanDescriptor> mean = StartDatabaseMean(source, image_ids);
    const MatcherCommandOptions resolved = ResolveOptionsForRun(
        checked, RowsOfImages(source, image_ids), [&](const std::string& text) { Info(callbacks, text); });
    clock.Mark("reading the feature counts");
    const ScheduleSizes sizes = ChooseSizesForRun(resolved, source, image_ids, callbacks);
    clock.Mark("starting the GPU and sizing the run");
    std::vector<PairChunk> chunks = ScheduledPairChunks(image_ids, sizes.block_size, sizes.blocks_per_group);
    const size_t n = image_ids.size();
    RunRequest request;
    request.options = resolved;
    request.source = &source;
    request.image_ids = image_ids;
    request.chunks = std::move(chunks);
    request.num_pairs_requested = n * (n - 1) / 2;
    request.cache_groups = true;
    request.matcher_keep_bytes = sizes.matcher_keep_bytes;
    request.mean = std::move(mean);
    request.clock = clock;
    return MatchChunks(std::move(request), callbacks);
  });
}

MatchingSummary MatchPairs(const std::string& database_path,
                           const std::vector<std::pair<std::string, std::string>>& image_name_pairs,
                           const MatcherCommandOptions& options, const MatchingCallbacks& all_callbacks) {
  return EndAllRanksOnError([&]() {
    PhaseClock clock;
    const MatchingCallbacks callbacks = CallbacksOfRank(all_callbacks);
    const MatcherCommandOptions checked = CheckedOptions(database_path, options);
    DatabaseFeatureSource source(database_path);
    if (callbacks.database_opened) callbacks.database_opened();
    clock.Mark("opening the database");
    return MatchIdPairs(checked, source, PairsOfNames(image_name_pairs, source), clock, callbacks);
  });
}

MatchingSummary MatchPairList(const std::string& database_path, const std::string& match_list_path,
                              const MatcherCommandOptions& options, const MatchingCallbacks& all_callbacks) {
  return EndAllRanksOnError([&]() {
    PhaseClock clock;
    const MatchingCallbacks callbacks = CallbacksOfRank(all_callbacks);
    const MatcherCommandOptions checked = CheckedOptions(database_path, options);
    DatabaseFeatureSource source(database_path);
    if (callbacks.database_opened) callbacks.database_opened();
    clock.Mark("opening the database");
    std::unordered_map<std::string, image_t> ids_by_name;
    for (const Image& image : source.images()) ids_by_name.emplace(image.name, image.image_id);
    std::ifstream file(match_list_path);
    if (!file) throw std::runtime_error("cannot open --match_list_path " + match_list_path);
    return MatchIdPairs(checked, source, ParsePairList(file, match_list_path, ids_by_name), clock, callbacks);
  });
}

}  // namespace colmap
}  // namespace cashash
