#include "colmap_bridge/api/retrieval_api.h"

#include <algorithm>
#include <chrono>
#include <ctime>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

#include "cashash/base/device_memory_error.h"
#include "cashash/base/pair_id.h"
#include "cashash/matching/mean_descriptor.h"
#include "cashash/base/parallel_for.h"
#include "cashash/pipeline/schedule_sizing.h"
#include "colmap_bridge/api/run_devices.h"
#include "colmap_bridge/api/run_plan.h"
#include "colmap_bridge/database.h"
#ifdef CASHASH_WITH_CUDA
#include "cashash_cuda/retrieval/image_retrieval_index.h"
#include "cashash_cuda/utils/gpu_resources.h"
#endif

namespace cashash {
namespace colmap {
namespace {

// The hashing mean comes from at most this many images spread evenly over
// the images, as the matcher's does (matching_api.cc).
constexpr size_t kMaxImagesForMean = 100;

// Processor time of the whole process, all threads (std::clock on POSIX).
double CpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

MeanDescriptor MeanOfImages(const Database& database, const std::vector<image_t>& image_ids) {
  std::vector<FeatureDescriptors> sample;
  const size_t n = image_ids.size();
  const size_t count = std::min(n, kMaxImagesForMean);
  for (size_t k = 0; k < count; ++k) sample.push_back(database.ReadDescriptors(image_ids[k * n / count]));
  std::vector<const FeatureDescriptors*> pointers;
  for (const FeatureDescriptors& d : sample) pointers.push_back(&d);
  return ComputeMeanDescriptor(pointers);
}

// The rows of an image's max_num_features largest-scale features, in row
// order (COLMAP's vocabulary tree indexes the largest scales too); empty
// for all rows.
std::vector<uint32_t> RowsToIndex(const Database& database, image_t image_id, size_t num_rows, int max_num_features) {
  if (max_num_features < 0 || num_rows <= static_cast<size_t>(max_num_features)) return {};
  const Keypoints keypoints = database.ReadKeypoints(image_id);
  std::vector<uint32_t> rows(std::min(keypoints.size(), num_rows));
  std::iota(rows.begin(), rows.end(), 0u);
  std::stable_sort(rows.begin(), rows.end(), [&keypoints](uint32_t a, uint32_t b) {
    return keypoints[a].ComputeScale() > keypoints[b].ComputeScale();
  });
  rows.resize(std::min(rows.size(), static_cast<size_t>(max_num_features)));
  std::sort(rows.begin(), rows.end());
  return rows;
}

size_t MedianRows(const Database& database, const std::vector<image_t>& image_ids, int max_num_features) {
  std::vector<size_t> rows;
  rows.reserve(image_ids.size());
  for (image_t id : image_ids) {
    size_t r = database.NumDescriptors(id);
    if (max_num_features > 0) r = std::min(r, static_cast<size_t>(max_num_features));
    rows.push_back(r);
  }
  if (rows.empty()) return 0;
  std::nth_element(rows.begin(), rows.begin() + static_cast<std::ptrdiff_t>(rows.size() / 2), rows.end());
  return rows[rows.size() / 2];
}

}  // namespace

DatabaseRetrievalIndex BuildDatabaseRetrievalIndex(const std::string& database_path, const RetrievalOptions& options,
                                                   std::vector<image_t> image_ids) {
  const std::string problem = options.Check();
  if (!problem.empty()) throw std::invalid_argument(problem);
  DatabaseRetrievalIndex result;
  auto start = std::chrono::steady_clock::now();
  const Database database(database_path, /*read_only=*/true);
  if (image_ids.empty()) {
    for (const Image& image : database.ReadAllImages()) image_ids.push_back(image.image_id);
  }
  result.image_ids = image_ids;
  const MeanDescriptor mean = MeanOfImages(database, image_ids);
  result.bits_per_word = RetrievalBitsPerWord(options, MedianRows(database, image_ids, options.max_num_features));
  result.seconds_mean = SecondsSince(start);

  start = std::chrono::steady_clock::now();
  double cpu_start = CpuSeconds();
  const VisualWordHasher hasher(options, result.bits_per_word, mean);
  std::vector<ImageWords> words(image_ids.size());
  std::vector<size_t> features(image_ids.size(), 0);
  const size_t workers = NumParallelWorkers(image_ids.size(), options.num_threads);
  std::vector<std::unique_ptr<Database>> readers(workers);
  ParallelForWorkers(image_ids.size(), options.num_threads, [&](size_t i, size_t worker) {
    if (!readers[worker]) readers[worker] = std::make_unique<Database>(database_path, /*read_only=*/true);
    const FeatureDescriptors descriptors = readers[worker]->ReadDescriptors(image_ids[i]);
    const std::vector<uint32_t> rows =
        RowsToIndex(*readers[worker], image_ids[i], descriptors.rows(), options.max_num_features);
    words[i] = hasher.Words(descriptors, rows);
    features[i] = rows.empty() ? descriptors.rows() : rows.size();
  });
  readers.clear();
  result.features_indexed = std::accumulate(features.begin(), features.end(), size_t{0});
  result.seconds_reading_and_hashing = SecondsSince(start);
  result.cpu_seconds_reading_and_hashing = CpuSeconds() - cpu_start;

  start = std::chrono::steady_clock::now();
  cpu_start = CpuSeconds();
  result.index = std::make_unique<ImageRetrievalIndex>(std::move(words), hasher.vocabulary_size(), options.num_threads,
                                                       options.max_word_image_fraction);
  result.seconds_indexing = SecondsSince(start);
  result.cpu_seconds_indexing = CpuSeconds() - cpu_start;
  return result;
}

RetrievalDevice RetrievalDeviceForRun(const MatcherCommandOptions& options) {
  RetrievalDevice device;
  // The devices' warnings are the matching run's to give.
  const RunDevices devices = ChooseRunDevices(options, MachineDeviceFacts());
  if (devices.gpu_indices.empty()) return device;
  device.gpu_index = devices.gpu_indices.front();
  if (!options.max_gpu_memory.empty() && !ParseMemorySize(options.max_gpu_memory, &device.memory_budget_bytes)) {
    throw std::invalid_argument("--max_gpu_memory " + options.max_gpu_memory + " is not a memory size");
  }
  return device;
}

std::string SearchPlace(int gpu_index) {
  return gpu_index < 0 ? "on the CPU" : "on GPU " + std::to_string(gpu_index);
}

NeighborSearch SearchNeighbors(const ImageRetrievalIndex& index, const std::vector<uint32_t>* images, size_t k,
                               const RetrievalDevice& device) {
  NeighborSearch search;
  if (device.gpu_index >= 0) {
#ifdef CASHASH_WITH_CUDA
    const RetrievalIndexView view = index.View();
    try {
      // The search's own owner of the device's memory, under the run's
      // budget: it gives everything back before the matchers start.
      cuda::GpuResources resources(device.gpu_index, device.memory_budget_bytes);
      cuda::GpuRetrievalConfig config;
      config.resources = &resources;
      search.neighbors = images != nullptr ? cuda::GpuTopK(view, *images, k, config) : cuda::GpuAllTopK(view, k, config);
      search.gpu_index = device.gpu_index;
      return search;
    } catch (const DeviceMemoryError& error) {
      search.gpu_fallback = "GPU " + std::to_string(device.gpu_index) + " has no room for the index (" +
                            std::to_string((cuda::GpuRetrievalResidentBytes(view) + (1u << 20) - 1) >> 20) +
                            " MiB of postings and word offsets): " + error.what();
    }
#else
    search.gpu_fallback = "cashash was built without CUDA";
#endif
  }
  search.neighbors = images != nullptr ? index.TopKOf(*images, k) : index.AllTopK(k);
  return search;
}

RetrievedPairs RetrievePairs(const DatabaseRetrievalIndex& index, const RetrievalOptions& options,
                             const RetrievalDevice& device) {
  const auto start = std::chrono::steady_clock::now();
  const double cpu_start = CpuSeconds();
  RetrievedPairs result;
  NeighborSearch search = SearchNeighbors(*index.index, nullptr, static_cast<size_t>(options.num_images), device);
  result.gpu_index = search.gpu_index;
  result.gpu_fallback = std::move(search.gpu_fallback);
  const auto neighbors = std::move(search.neighbors);
  for (const auto& [a, b] : UnionOfNeighborPairs(neighbors)) {
    const image_t id1 = index.image_ids[a];
    const image_t id2 = index.image_ids[b];
    result.pairs.emplace_back(std::min(id1, id2), std::max(id1, id2));
  }
  std::sort(result.pairs.begin(), result.pairs.end());
  result.seconds_querying = SecondsSince(start);
  result.cpu_seconds_querying = CpuSeconds() - cpu_start;
  return result;
}

namespace {

std::string FormatSeconds(double seconds) {
  std::ostringstream out;
  out.setf(std::ios::fixed);
  out.precision(3);
  out << seconds << " s";
  return out.str();
}

std::vector<std::pair<std::string, std::string>> NamesOfPairs(const Database& database,
                                                              const std::vector<ImagePair>& pairs) {
  std::unordered_map<image_t, std::string> names;
  for (const Image& image : database.ReadAllImages()) names.emplace(image.image_id, image.name);
  std::vector<std::pair<std::string, std::string>> named;
  named.reserve(pairs.size());
  for (const ImagePair& pair : pairs) named.emplace_back(names.at(pair.first), names.at(pair.second));
  return named;
}

// The pairs the verified graph implies and that were never tried: i-k for
// every i-j and j-k with at least min_num_inliers inliers each.
std::vector<ImagePair> TransitivePairs(const std::string& database_path, int min_num_inliers) {
  const Database database(database_path, /*read_only=*/true);
  std::unordered_set<pair_t> tried;
  database.ForEachCompletedPairId([&tried](pair_t pair_id) { tried.insert(pair_id); });
  std::unordered_map<image_t, std::vector<image_t>> neighbors;
  for (pair_t pair_id : tried) {
    const ImagePair pair = PairIdToImagePair(pair_id);
    const TwoViewGeometry geometry = database.ReadTwoViewGeometry(pair.first, pair.second);
    if (static_cast<int>(geometry.inlier_matches.size()) < min_num_inliers) continue;
    neighbors[pair.first].push_back(pair.second);
    neighbors[pair.second].push_back(pair.first);
  }
  std::unordered_set<pair_t> implied;
  for (auto& [image, around] : neighbors) {
    std::sort(around.begin(), around.end());
    for (size_t a = 0; a < around.size(); ++a) {
      for (size_t b = a + 1; b < around.size(); ++b) {
        const pair_t pair_id = ImagePairToPairId(around[a], around[b]);
        if (!tried.count(pair_id)) implied.insert(pair_id);
      }
    }
  }
  std::vector<ImagePair> pairs;
  for (pair_t pair_id : implied) pairs.push_back(PairIdToImagePair(pair_id));
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

// The first part's pipeline whole (its stage times included), later parts'
// counts and wall time added.
void AddUp(const MatchingSummary& part, MatchingSummary* total) {
  const bool first = total->matcher_name.empty() && total->pipeline.pairs_total == 0;
  total->pairs_requested += part.pairs_requested;
  total->pairs_skipped += part.pairs_skipped;
  if (!part.matcher_name.empty()) total->matcher_name = part.matcher_name;
  PipelineStats& t = total->pipeline;
  const PipelineStats& p = part.pipeline;
  if (first) {
    t = p;
  } else {
    t.pairs_total += p.pairs_total;
    t.pairs_done += p.pairs_done;
    t.raw_matches += p.raw_matches;
    t.verified_pairs += p.verified_pairs;
    t.inlier_matches += p.inlier_matches;
    t.seconds_total += p.seconds_total;
    t.stopped = t.stopped || p.stopped;
  }
  total->phases_outside_pipeline.insert(total->phases_outside_pipeline.end(), part.phases_outside_pipeline.begin(),
                                        part.phases_outside_pipeline.end());
}

}  // namespace

MatchingSummary MatchRetrieval(const std::string& database_path, const MatcherCommandOptions& options,
                               const MatchingCallbacks& callbacks) {
  MatcherCommandOptions checked = options;
  checked.database_path = database_path;
  const std::string problem = CheckMatcherCommandOptions(checked);
  if (!problem.empty()) throw std::invalid_argument(problem);
  std::vector<image_t> image_ids;
  std::vector<std::pair<std::string, std::string>> named_pairs;
  MatchingSummary summary;
  {
    const Database database(database_path, /*read_only=*/true);
    if (callbacks.database_opened) callbacks.database_opened();
    if (!checked.vocab_tree_path.empty()) {
      Warn(callbacks, "--VocabTreeMatching.vocab_tree_path " + checked.vocab_tree_path +
                          " is not used: cashash takes its visual words from the hash codes of the database's "
                          "own descriptors");
    }
    for (const Image& image : database.ReadAllImages()) image_ids.push_back(image.image_id);
    if (image_ids.size() < 2) {
      Warn(callbacks, "table images of " + database_path + " holds " + std::to_string(image_ids.size()) + " image" +
                          (image_ids.size() == 1 ? "" : "s") + "; nothing to match");
      return summary;
    }
    RetrievalOptions retrieval = checked.retrieval;
    retrieval.random_seed = checked.random_seed;
    retrieval.num_threads = checked.sift.num_threads;
    const DatabaseRetrievalIndex index = BuildDatabaseRetrievalIndex(database_path, retrieval, image_ids);
    const RetrievedPairs retrieved = RetrievePairs(index, retrieval, RetrievalDeviceForRun(checked));
    if (!retrieved.gpu_fallback.empty()) Warn(callbacks, "retrieval: " + retrieved.gpu_fallback + "; querying on the CPU");
    const double n = static_cast<double>(image_ids.size());
    std::ostringstream line;
    line.setf(std::ios::fixed);
    line.precision(1);
    line << "Retrieval: " << image_ids.size() << " images, " << index.features_indexed << " features, "
         << retrieval.num_tables << " x " << index.bits_per_word << "-bit words (" << retrieval.num_nearest_neighbors
         << " per query feature and table); " << retrieved.pairs.size() << " pairs, "
         << 100.0 * retrieved.pairs.size() / (0.5 * n * (n - 1)) << " % of all, for the " << retrieval.num_images
         << " most similar images of each";
    Info(callbacks, line.str());
    Info(callbacks, "Retrieval time: mean " + FormatSeconds(index.seconds_mean) + ", reading and hashing " +
                        FormatSeconds(index.seconds_reading_and_hashing) + ", indexing " +
                        FormatSeconds(index.seconds_indexing) + ", querying " +
                        FormatSeconds(retrieved.seconds_querying) + " " + SearchPlace(retrieved.gpu_index));
    summary.phases_outside_pipeline = {{"retrieval: mean descriptor", index.seconds_mean},
                                       {"retrieval: reading and hashing", index.seconds_reading_and_hashing},
                                       {"retrieval: indexing", index.seconds_indexing},
                                       {"retrieval: querying", retrieved.seconds_querying}};
    named_pairs = NamesOfPairs(database, retrieved.pairs);
  }
  MatchingCallbacks inner = callbacks;
  inner.database_opened = nullptr;  // the heading is printed once
  const MatchingSummary matched = MatchPairs(database_path, named_pairs, checked, inner);
  AddUp(matched, &summary);
  summary.gpu_index = matched.gpu_index;
  summary.gpu_total_bytes = matched.gpu_total_bytes;
  summary.gpu_used_before_bytes = matched.gpu_used_before_bytes;
  summary.gpu_peak_used_bytes = matched.gpu_peak_used_bytes;
  summary.run = matched.run;
  for (int round = 1; round <= checked.transitive_rounds && !summary.pipeline.stopped; ++round) {
    const std::vector<ImagePair> implied = TransitivePairs(database_path, checked.two_view.min_num_inliers);
    Info(callbacks, "Transitive round " + std::to_string(round) + ": " + std::to_string(implied.size()) +
                        " pairs implied by the verified pairs");
    if (implied.empty()) break;
    const Database database(database_path, /*read_only=*/true);
    AddUp(MatchPairs(database_path, NamesOfPairs(database, implied), checked, inner), &summary);
  }
  return summary;
}

}  // namespace colmap
}  // namespace cashash
