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
#include "colmap_bridge/api/pair_selection.h"
#include "colmap_bridge/api/run_devices.h"
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

// What the database and the machine say about a run, for ResolveRun: the
// images' feature rows, the run's usable devices and, for an exhaustive
// run, the memory to size its blocks and groups from; reduced over MPI
// ranks, so that all resolve the same run.
RunFacts GatherRunFacts(const MatcherCommandOptions& options, std::vector<size_t> rows_per_image, bool exhaustive) {
  RunFacts facts;
  facts.rows_per_image = std::move(rows_per_image);
  facts.exhaustive = exhaustive;
  RunDevices devices = ChooseRunDevices(options, MachineDeviceFacts());
  facts.gpu_indices = std::move(devices.gpu_indices);
  facts.device_warnings = std::move(devices.warnings);
  if (exhaustive) {
    facts.physical_memory_bytes = PhysicalMemoryBytes();
    if (!facts.gpu_indices.empty() && options.max_gpu_memory.empty()) {
      facts.gpu_free_bytes = GpuFreeMemoryBytes(facts.gpu_indices.front());
    }
  }
  facts.smallest_over_ranks = [](uint64_t value) { return MpiMin(value); };
  return facts;
}

// The run of `options` over `facts`; says what was chosen, as the command
// line prints it.
ResolvedRun ResolveAndReport(const MatcherCommandOptions& options, const RunFacts& facts,
                             const MatchingCallbacks& callbacks) {
  ResolvedRun run = ResolveRun(options, facts);
  // The tables first, then the schedule's warning and the schedule.
  if (!run.notes.empty() && facts.exhaustive) {
    for (size_t k = 0; k + 1 < run.notes.size(); ++k) Info(callbacks, run.notes[k]);
    for (const std::string& warning : run.warnings) Warn(callbacks, warning);
    Info(callbacks, run.notes.back());
  } else {
    for (const std::string& note : run.notes) Info(callbacks, note);
    for (const std::string& warning : run.warnings) Warn(callbacks, warning);
  }
  return run;
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
                             const std::vector<ImagePair>& pairs, PhaseClock clock,
                             const MatchingCallbacks& callbacks) {
  const std::vector<image_t> image_ids = ImagesOfPairs(pairs);
  std::shared_future<MeanDescriptor> mean = StartDatabaseMean(source, image_ids);
  std::vector<size_t> rows = RowsOfImages(source, image_ids);
  clock.Mark("reading the pairs and feature counts");
  const RunFacts facts = GatherRunFacts(options, std::move(rows), /*exhaustive=*/false);
  clock.Mark("starting the GPU and sizing the run");
  RunRequest request;
  request.run = ResolveAndReport(options, facts, callbacks);
  const size_t block = static_cast<size_t>(request.run.options.block_size);
  request.source = &source;
  request.image_ids = image_ids;
  request.chunks = ListPairChunks(pairs, block * block, 2 * block);
  request.num_pairs_requested = pairs.size();
  request.mean = std::move(mean);
  request.clock = clock;
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

namespace {

// What each public entry point does first, once: under MPI an error on any
// rank ends them all; this rank's callbacks; the options checked as the
// command line checks them; the database opened (its data warnings through
// the callbacks). `body(checked options, source, clock, callbacks)` does
// the rest.
template <typename Body>
MatchingSummary RunOnDatabase(const std::string& database_path, const MatcherCommandOptions& options,
                              const MatchingCallbacks& all_callbacks, Body body) {
  return EndAllRanksOnError([&]() {
    PhaseClock clock;
    const MatchingCallbacks callbacks = CallbacksOfRank(all_callbacks);
    const MatcherCommandOptions checked = CheckedOptions(database_path, options);
    DatabaseFeatureSource source(database_path, [&callbacks](const std::string& text) { Warn(callbacks, text); });
    if (callbacks.database_opened) callbacks.database_opened();
    clock.Mark("opening the database");
    return body(checked, source, clock, callbacks);
  });
}

}  // namespace

MatchingSummary MatchExhaustive(const std::string& database_path, const MatcherCommandOptions& options,
                                const MatchingCallbacks& all_callbacks) {
  return RunOnDatabase(database_path, options, all_callbacks,
                       [&](const MatcherCommandOptions& checked, DatabaseFeatureSource& source, PhaseClock clock,
                           const MatchingCallbacks& callbacks) {
    const std::vector<image_t> image_ids = ImageIds(source);
    if (image_ids.size() < 2) {
      Warn(callbacks, "table images of " + database_path + " holds " + std::to_string(image_ids.size()) + " image" +
                          (image_ids.size() == 1 ? "" : "s") + "; nothing to match");
      return MatchingSummary();
    }
    std::shared_future<MeanDescriptor> mean = StartDatabaseMean(source, image_ids);
    std::vector<size_t> rows = RowsOfImages(source, image_ids);
    clock.Mark("reading the feature counts");
    const RunFacts facts = GatherRunFacts(checked, std::move(rows), /*exhaustive=*/true);
    RunRequest request;
    request.run = ResolveAndReport(checked, facts, callbacks);
    clock.Mark("starting the GPU and sizing the run");
    const size_t n = image_ids.size();
    request.source = &source;
    request.image_ids = image_ids;
    request.exhaustive = true;
    request.num_pairs_requested = n * (n - 1) / 2;
    request.mean = std::move(mean);
    request.clock = clock;
    return MatchChunks(std::move(request), callbacks);
  });
}

MatchingSummary MatchPairs(const std::string& database_path,
                           const std::vector<std::pair<std::string, std::string>>& image_name_pairs,
                           const MatcherCommandOptions& options, const MatchingCallbacks& all_callbacks) {
  return RunOnDatabase(database_path, options, all_callbacks,
                       [&](const MatcherCommandOptions& checked, DatabaseFeatureSource& source, PhaseClock clock,
                           const MatchingCallbacks& callbacks) {
    return MatchIdPairs(checked, source, PairsOfNames(image_name_pairs, source), clock, callbacks);
  });
}

MatchingSummary MatchPairList(const std::string& database_path, const std::string& match_list_path,
                              const MatcherCommandOptions& options, const MatchingCallbacks& all_callbacks) {
  return RunOnDatabase(database_path, options, all_callbacks,
                       [&](const MatcherCommandOptions& checked, DatabaseFeatureSource& source, PhaseClock clock,
                           const MatchingCallbacks& callbacks) {
    std::unordered_map<std::string, image_t> ids_by_name;
    for (const Image& image : source.images()) ids_by_name.emplace(image.name, image.image_id);
    std::ifstream file(match_list_path);
    if (!file) throw std::runtime_error("cannot open --match_list_path " + match_list_path);
    return MatchIdPairs(checked, source, ParsePairList(file, match_list_path, ids_by_name), clock, callbacks);
  });
}

namespace {

// Reports the chosen pairs and matches them; the pair list's path.
MatchingSummary MatchSelectedPairs(const MatcherCommandOptions& options, DatabaseFeatureSource& source,
                                   const SelectedPairs& selected, PhaseClock clock,
                                   const MatchingCallbacks& callbacks) {
  for (const std::string& note : selected.notes) Info(callbacks, note);
  for (const std::string& warning : selected.warnings) Warn(callbacks, warning);
  clock.Mark("choosing the pairs");
  if (selected.pairs.empty()) {
    Info(callbacks, "Nothing to match.");
    return MatchingSummary();
  }
  return MatchIdPairs(options, source, selected.pairs, clock, callbacks);
}

}  // namespace

MatchingSummary MatchSequential(const std::string& database_path, const MatcherCommandOptions& options,
                                const MatchingCallbacks& all_callbacks, ImageRetrieval* retrieval) {
  return RunOnDatabase(database_path, options, all_callbacks,
                       [&](const MatcherCommandOptions& checked, DatabaseFeatureSource& source, PhaseClock clock,
                           const MatchingCallbacks& callbacks) {
    std::unique_ptr<ImageRetrieval> own_retrieval;
    if (checked.sequential.loop_detection && retrieval == nullptr) {
      std::vector<image_t> image_ids;
      for (const Image& image : source.images()) image_ids.push_back(image.image_id);
      RetrievalMessages messages;
      messages.info = [callbacks](const std::string& text) { Info(callbacks, text); };
      messages.warning = [callbacks](const std::string& text) { Warn(callbacks, text); };
      own_retrieval = CreateImageRetrievalForRun(checked, database_path, image_ids, std::move(messages));
      retrieval = own_retrieval.get();
    }
    const SelectedPairs selected =
        SelectSequentialPairs(source.database(), source.images(), checked.sequential, retrieval);
    return MatchSelectedPairs(checked, source, selected, clock, callbacks);
  });
}

MatchingSummary MatchSpatial(const std::string& database_path, const MatcherCommandOptions& options,
                             const MatchingCallbacks& all_callbacks) {
  return RunOnDatabase(database_path, options, all_callbacks,
                       [&](const MatcherCommandOptions& checked, DatabaseFeatureSource& source, PhaseClock clock,
                           const MatchingCallbacks& callbacks) {
    const SelectedPairs selected = SelectSpatialPairs(source.database(), source.images(), checked.spatial);
    return MatchSelectedPairs(checked, source, selected, clock, callbacks);
  });
}

}  // namespace colmap
}  // namespace cashash
