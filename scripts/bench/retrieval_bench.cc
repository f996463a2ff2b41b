// Time and recall of image retrieval from the hash codes (docs/retrieval.md)
// on a COLMAP database, without matching anything:
//
//   retrieval_bench --database DB [--num_images K] [--num_tables T]
//       [--bits_per_word B] [--num_nearest_neighbors P]
//       [--max_num_features M] [--threads N] [--seed S]
//       [--truth EXHAUSTIVE_DB] [--min_inliers 15] [--strong_inliers 50]
//       [--pairs_out FILE] [--max_images N]
//       [--use_gpu 0|1] [--gpu_index G] [--max_gpu_memory SIZE]
//   retrieval_bench --database SOURCE_DB --synthetic_images N
//       [--synthetic_features F] [--compare_cpu 0|1] [options]
//
// --use_gpu 1 runs the queries on GPU G (default 0) as the command does
// with a GPU (docs/retrieval.md, "Queries on the GPU"), under
// --max_gpu_memory if given; the rest runs on the CPU either way. With
// --synthetic_images, --compare_cpu 1 also queries on the CPU and prints
// both times and the share of images whose neighbour lists are identical.
//
// Prints the wall time of each phase (mean descriptor; reading and hashing
// every image; building the inverted file; querying every image), the
// postings the queries read and the pairs chosen. With --truth (a copy of
// DB matched exhaustively), also the share of the pairs verified there
// with at least --strong_inliers and at least --min_inliers inliers that
// retrieval chose (matching the chosen pairs verifies the same pairs: the
// matcher and verifier see each pair alone). --pairs_out writes the pairs
// as a matches_importer list; --max_images indexes the first N images only
// (one generated database then gives every size of a scale table).
//
// --synthetic_images: no database of that size is read; N street images of
// F features (default 4,096) are made in memory from the SOURCE_DB's
// descriptors as `cashash generate_database` makes them (each image sees a
// stretch of points that its neighbours along the street share, every view
// with its own descriptor noise, each stretch of street with its own
// reordering of the descriptor values, 30 % distractors), then hashed,
// indexed and queried. The times leave out reading the descriptors from
// SQLite; time that on a generated database of the same features.
#include <sqlite3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <numeric>
#include <random>
#include <cstdlib>
#include <fstream>
#include <map>
#include <mutex>
#include <array>
#include <set>
#include <stdexcept>
#include <string>

#include "cashash/base/pair_id.h"
#include "cashash/base/parallel_for.h"
#include "cashash/pipeline/schedule_sizing.h"
#include "colmap_bridge/api/retrieval_api.h"
#include "colmap_bridge/database.h"

namespace {

using namespace cashash;

std::map<pair_t, int> VerifiedInliers(const std::string& path) {
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) {
    throw std::runtime_error("cannot open " + path);
  }
  sqlite3_stmt* statement = nullptr;
  sqlite3_prepare_v2(db, "SELECT pair_id, rows FROM two_view_geometries", -1, &statement, nullptr);
  std::map<pair_t, int> inliers;
  while (sqlite3_step(statement) == SQLITE_ROW) {
    inliers[static_cast<pair_t>(sqlite3_column_int64(statement, 0))] = sqlite3_column_int(statement, 1);
  }
  sqlite3_finalize(statement);
  sqlite3_close(db);
  return inliers;
}

double CpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

double ThreadCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

double WallSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Descriptors of the first images of `path` (at most 24), the pool the
// synthetic images draw from.
std::vector<std::array<uint8_t, kDescriptorDim>> DescriptorPool(const std::string& path) {
  const colmap::Database db(path, /*read_only=*/true);
  std::vector<std::array<uint8_t, kDescriptorDim>> pool;
  const std::vector<Image> images = db.ReadAllImages();
  for (size_t k = 0; k < images.size() && k < 24; ++k) {
    const FeatureDescriptors d = db.ReadDescriptors(images[k].image_id);
    for (size_t r = 0; r < d.rows(); ++r) {
      std::array<uint8_t, kDescriptorDim> row;
      std::copy(d.row(r), d.row(r) + kDescriptorDim, row.begin());
      pool.push_back(row);
    }
  }
  if (pool.empty()) throw std::runtime_error(path + " holds no descriptors");
  return pool;
}

uint64_t Mix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Image i of a synthetic street: it sees points of the window [i, i + 10)
// street units (each unit holding points_per_unit points), so it shares
// points with its nine neighbours on either side; 70 % of its features are
// views of those points, 30 % distractors.
FeatureDescriptors SyntheticImage(const std::vector<std::array<uint8_t, kDescriptorDim>>& pool, int image,
                                  int num_features) {
  constexpr int kWindow = 10;
  constexpr int kStretch = 50;  // units of street sharing one reordering of the values
  const int observed = num_features * 7 / 10;
  const uint64_t points_per_unit = static_cast<uint64_t>(observed) * 2 / kWindow;
  std::mt19937_64 rng(Mix(static_cast<uint64_t>(image) + 1));
  std::uniform_real_distribution<float> sigma(2.f, 12.f);
  FeatureDescriptors d;
  d.data.resize(static_cast<size_t>(num_features) * kDescriptorDim);
  for (int f = 0; f < num_features; ++f) {
    uint64_t source, stretch;
    if (f < observed) {
      const uint64_t unit = static_cast<uint64_t>(image) + rng() % kWindow;
      const uint64_t point = unit * points_per_unit + rng() % points_per_unit;
      source = Mix(point) % pool.size();
      stretch = unit / kStretch;
    } else {
      source = rng() % pool.size();
      stretch = rng();
    }
    // The stretch's reordering of the values: a rotation and a reflection.
    const int shift = static_cast<int>(Mix(stretch) % kDescriptorDim);
    const bool reflect = (Mix(stretch + 7) & 1) != 0;
    const float s = sigma(rng);
    uint8_t* out = d.data.data() + static_cast<size_t>(f) * kDescriptorDim;
    for (int k = 0; k < kDescriptorDim; ++k) {
      const int from = reflect ? (kDescriptorDim - 1 - (k + shift) % kDescriptorDim) : (k + shift) % kDescriptorDim;
      // Noise of standard deviation s, cheaply: four 16-bit uniforms of one
      // draw summed (Irwin-Hall, variance 4/12), centred and scaled.
      const uint64_t r = rng();
      const float u = static_cast<float>((r & 0xFFFF) + ((r >> 16) & 0xFFFF) + ((r >> 32) & 0xFFFF) + (r >> 48)) /
                          65536.f - 2.f;
      const float v = pool[source][from] + s * 1.7320508f * u;
      out[k] = static_cast<uint8_t>(std::clamp(std::lround(v), 0l, 255l));
    }
  }
  return d;
}

// Share of the images whose lists hold the same images in the same order.
double IdenticalShare(const std::vector<std::vector<RetrievalNeighbor>>& a,
                      const std::vector<std::vector<RetrievalNeighbor>>& b) {
  size_t same = 0;
  for (size_t i = 0; i < a.size() && i < b.size(); ++i) {
    bool equal = a[i].size() == b[i].size();
    for (size_t r = 0; equal && r < a[i].size(); ++r) equal = a[i][r].image == b[i][r].image;
    same += equal;
  }
  return a.empty() ? 1.0 : static_cast<double>(same) / static_cast<double>(a.size());
}

// Hash, index and query synthetic images; prints the times.
void RunSynthetic(const std::string& source, int num_images, int num_features, const RetrievalOptions& options,
                  const colmap::RetrievalDevice& device, bool compare_cpu) {
  const auto pool = DescriptorPool(source);
  std::vector<FeatureDescriptors> sample;
  for (int k = 0; k < std::min(num_images, 100); ++k) {
    sample.push_back(SyntheticImage(pool, k * num_images / std::min(num_images, 100), num_features));
  }
  std::vector<const FeatureDescriptors*> pointers;
  for (const FeatureDescriptors& d : sample) pointers.push_back(&d);
  const VisualWordHasher hasher(options, RetrievalBitsPerWord(options, static_cast<size_t>(num_features)),
                                ComputeMeanDescriptor(pointers));
  // Making the descriptors is not part of retrieval: made first, then hashed.
  double wall = WallSeconds(), cpu = CpuSeconds();
  std::vector<ImageWords> words(static_cast<size_t>(num_images));
  double making = 0, hashing = 0;
  std::mutex making_mutex;
  ParallelFor(words.size(), options.num_threads, [&](size_t i) {
    const double made = ThreadCpuSeconds();
    const FeatureDescriptors d = SyntheticImage(pool, static_cast<int>(i), num_features);
    const double hashed = ThreadCpuSeconds();
    words[i] = hasher.Words(d);
    const double done = ThreadCpuSeconds();
    std::lock_guard<std::mutex> lock(making_mutex);
    making += hashed - made;
    hashing += done - hashed;
  });
  const double hashing_wall = WallSeconds() - wall, hashing_cpu = CpuSeconds() - cpu;
  wall = WallSeconds();
  cpu = CpuSeconds();
  const ImageRetrievalIndex index(std::move(words), hasher.vocabulary_size(), options.num_threads,
                                  options.max_word_image_fraction);
  const double indexing_wall = WallSeconds() - wall, indexing_cpu = CpuSeconds() - cpu;
  wall = WallSeconds();
  cpu = CpuSeconds();
  colmap::NeighborSearch search =
      colmap::SearchNeighbors(index, nullptr, static_cast<size_t>(options.num_images), device);
  const auto neighbors = std::move(search.neighbors);
  const auto pairs = UnionOfNeighborPairs(neighbors);
  const double querying_wall = WallSeconds() - wall, querying_cpu = CpuSeconds() - cpu;
  if (!search.gpu_fallback.empty()) std::printf("GPU fallback: %s\n", search.gpu_fallback.c_str());
  std::printf("querying %s\n", colmap::SearchPlace(search.gpu_index).c_str());
  if (compare_cpu && search.gpu_index >= 0) {
    const double cpu_wall = WallSeconds();
    const auto on_cpu = index.AllTopK(static_cast<size_t>(options.num_images));
    std::printf("querying on the CPU: wall seconds %.3f (GPU %.3f), identical neighbour lists %.4f\n",
                WallSeconds() - cpu_wall, querying_wall, IdenticalShare(neighbors, on_cpu));
  }
  // Views of the same stretch: how many of each image's 2 x 9 overlapping neighbours it retrieved.
  size_t near = 0;
  for (size_t i = 0; i < neighbors.size(); ++i) {
    for (const RetrievalNeighbor& n : neighbors[i]) near += std::abs(static_cast<long>(n.image) - static_cast<long>(i)) <= 9;
  }
  std::printf("synthetic street: %d images x %d features, %d tables x %d bits, threads %zu\n", num_images, num_features,
              options.num_tables, hasher.bits_per_word(), static_cast<size_t>(ResolveNumThreads(options.num_threads)));
  std::printf("wall seconds: making and hashing %.3f, indexing %.3f, querying %.3f\n", hashing_wall, indexing_wall,
              querying_wall);
  std::printf("cpu seconds: making the descriptors %.3f (not retrieval), hashing %.3f, indexing %.3f, querying %.3f\n",
              making, hashing, indexing_cpu, querying_cpu);
  (void)hashing_cpu;
  std::printf("postings read by the queries %llu, pairs %zu, neighbours within 9 along the street among the retrieved %.4f\n",
              static_cast<unsigned long long>(index.PostingsReadByAllQueries()), pairs.size(),
              static_cast<double>(near) / (static_cast<double>(num_images) * options.num_images));
}

}  // namespace

int main(int argc, char** argv) {
  std::string database, truth, pairs_out;
  RetrievalOptions options;
  options.num_images = 50;  // the scale target's
  int min_inliers = 15, strong_inliers = 50, max_images = 0, synthetic_images = 0, synthetic_features = 4096;
  bool use_gpu = false, compare_cpu = false;
  int gpu_index = 0;
  std::string max_gpu_memory;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string key = argv[i];
    const std::string value = argv[i + 1];
    if (key == "--database") database = value;
    else if (key == "--truth") truth = value;
    else if (key == "--pairs_out") pairs_out = value;
    else if (key == "--num_images") options.num_images = std::stoi(value);
    else if (key == "--num_tables") options.num_tables = std::stoi(value);
    else if (key == "--bits_per_word") options.bits_per_word = std::stoi(value);
    else if (key == "--num_nearest_neighbors") options.num_nearest_neighbors = std::stoi(value);
    else if (key == "--max_num_features") options.max_num_features = std::stoi(value);
    else if (key == "--threads") options.num_threads = std::stoi(value);
    else if (key == "--seed") options.random_seed = std::stoull(value);
    else if (key == "--max_word_image_fraction") options.max_word_image_fraction = std::stod(value);
    else if (key == "--min_inliers") min_inliers = std::stoi(value);
    else if (key == "--max_images") max_images = std::stoi(value);
    else if (key == "--synthetic_images") synthetic_images = std::stoi(value);
    else if (key == "--synthetic_features") synthetic_features = std::stoi(value);
    else if (key == "--strong_inliers") strong_inliers = std::stoi(value);
    else if (key == "--use_gpu") use_gpu = std::stoi(value) != 0;
    else if (key == "--gpu_index") gpu_index = std::stoi(value);
    else if (key == "--max_gpu_memory") max_gpu_memory = value;
    else if (key == "--compare_cpu") compare_cpu = std::stoi(value) != 0;
    else {
      std::fprintf(stderr, "unknown option %s\n", key.c_str());
      return 1;
    }
  }
  if (database.empty()) {
    std::fprintf(stderr, "usage: retrieval_bench --database DB [--truth EXHAUSTIVE_DB] [options]\n");
    return 1;
  }
  colmap::RetrievalDevice device;
  if (use_gpu) {
    device.gpu_index = gpu_index;
    if (!max_gpu_memory.empty() && !ParseMemorySize(max_gpu_memory, &device.memory_budget_bytes)) {
      std::fprintf(stderr, "--max_gpu_memory %s is not a memory size\n", max_gpu_memory.c_str());
      return 1;
    }
  }
  try {
    if (synthetic_images > 0) {
      RunSynthetic(database, synthetic_images, synthetic_features, options, device, compare_cpu);
      return 0;
    }
    std::vector<image_t> image_ids;
    if (max_images > 0) {
      const colmap::Database db(database, /*read_only=*/true);
      for (const Image& image : db.ReadAllImages()) {
        if (static_cast<int>(image_ids.size()) < max_images) image_ids.push_back(image.image_id);
      }
    }
    const colmap::DatabaseRetrievalIndex index = colmap::BuildDatabaseRetrievalIndex(database, options, image_ids);
    const colmap::RetrievedPairs retrieved = colmap::RetrievePairs(index, options, device);
    if (!retrieved.gpu_fallback.empty()) std::printf("GPU fallback: %s\n", retrieved.gpu_fallback.c_str());
    std::printf("querying %s\n", colmap::SearchPlace(retrieved.gpu_index).c_str());
    const size_t n = index.image_ids.size();
    const double all_pairs = 0.5 * static_cast<double>(n) * static_cast<double>(n - 1);
    std::printf("images %zu, features %zu, %d tables x %d bits, %d words per feature and table per query\n", n,
                index.features_indexed, options.num_tables, index.bits_per_word, options.num_nearest_neighbors);
    std::printf("seconds: mean %.3f, reading+hashing %.3f, indexing %.3f, querying %.3f, total %.3f\n",
                index.seconds_mean, index.seconds_reading_and_hashing, index.seconds_indexing,
                retrieved.seconds_querying,
                index.seconds_mean + index.seconds_reading_and_hashing + index.seconds_indexing +
                    retrieved.seconds_querying);
    std::printf("cpu seconds: reading+hashing %.3f, indexing %.3f, querying %.3f\n",
                index.cpu_seconds_reading_and_hashing, index.cpu_seconds_indexing, retrieved.cpu_seconds_querying);
    std::printf("postings read by the queries %llu\n",
                static_cast<unsigned long long>(index.index->PostingsReadByAllQueries()));
    std::printf("pairs %zu of %.0f (%.4f), num_images %d\n", retrieved.pairs.size(), all_pairs,
                retrieved.pairs.size() / all_pairs, options.num_images);
    if (!truth.empty()) {
      std::set<pair_t> chosen;
      for (const ImagePair& p : retrieved.pairs) chosen.insert(ImagePairToPairId(p.first, p.second));
      size_t strong = 0, strong_found = 0, verified = 0, verified_found = 0;
      for (const auto& [pair_id, inliers] : VerifiedInliers(truth)) {
        const bool found = chosen.count(pair_id) > 0;
        if (inliers >= min_inliers) {
          ++verified;
          verified_found += found;
        }
        if (inliers >= strong_inliers) {
          ++strong;
          strong_found += found;
        }
      }
      std::printf("recall: >=%d inliers %zu/%zu (%.4f), >=%d inliers %zu/%zu (%.4f)\n", strong_inliers,
                  strong_found, strong, strong ? double(strong_found) / strong : 1.0, min_inliers, verified_found,
                  verified, verified ? double(verified_found) / verified : 1.0);
    }
    if (!pairs_out.empty()) {
      const colmap::Database db(database, /*read_only=*/true);
      std::map<image_t, std::string> names;
      for (const Image& image : db.ReadAllImages()) names[image.image_id] = image.name;
      std::ofstream out(pairs_out);
      for (const ImagePair& p : retrieved.pairs) out << names[p.first] << " " << names[p.second] << "\n";
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ERROR: %s\n", e.what());
    return 1;
  }
  return 0;
}
