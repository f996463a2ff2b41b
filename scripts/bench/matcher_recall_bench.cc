// Recall and speed of the CPU Cascade Hashing matcher against exact brute
// force on the SIFT descriptors of a COLMAP database, for several
// (tables, bits, tau, top_k) settings. Prints a markdown table.
//
//   matcher_recall_bench --database DB [--max_pairs N] [--max_images N]
//       [--threads T] [--seed S] [--settings "6,8,48,10;8,10,48,10;auto"]
//
// "auto" (or "auto,tau,top_k") is the shape cashash chooses for the
// database's median features per image (table_shape.h), tau 43 / top_k 16
// unless given. --max_images reads only the first N images.
//
// Recall = fraction of the brute-force matches (mutual, ratio test, COLMAP
// defaults) that the cascade also returns; precision = fraction of the
// cascade matches that brute force returns. Candidates are per query and
// direction: bucket entries visited (a feature sharing k tables counts k
// times), distinct candidates within tau, and those ranked (exact dot). Times are single-pair wall times summed
// over pairs, divided by the number of threads used.
#include <sqlite3.h>
#include <time.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "cashash/matching/brute_force_matcher.h"
#include "cashash/matching/cascade_hashing.h"
#include "cashash/matching/cascade_matcher.h"
#include "cashash/matchers/feature_matcher.h"
#include "cashash/matching/table_shape.h"
#include "cashash/base/parallel_for.h"
#include "../../tests/support/cascade_options.h"

namespace {

using namespace cashash;
using cashash::testing_support::CascadeOptions;

double CpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

// Raw matches COLMAP stored for (id1 < id2), or false when the pair has no row.
bool ReadColmapMatches(sqlite3* db, int64_t id1, int64_t id2, FeatureMatches* matches) {
  sqlite3_stmt* stmt = nullptr;
  if (sqlite3_prepare_v2(db, "SELECT rows, cols, data FROM matches WHERE pair_id = ?", -1, &stmt,
                         nullptr) != SQLITE_OK) {
    return false;
  }
  sqlite3_bind_int64(stmt, 1, 2147483647LL * id1 + id2);
  bool found = false;
  if (sqlite3_step(stmt) == SQLITE_ROW) {
    found = true;
    const int64_t rows = sqlite3_column_int64(stmt, 0);
    const auto* data = static_cast<const uint32_t*>(sqlite3_column_blob(stmt, 2));
    matches->clear();
    for (int64_t r = 0; r < rows; ++r) matches->push_back({data[2 * r], data[2 * r + 1]});
    std::sort(matches->begin(), matches->end());
  }
  sqlite3_finalize(stmt);
  return found;
}

std::vector<FeatureDescriptors> ReadAllDescriptors(const std::string& path, size_t max_images,
                                                   std::vector<int64_t>* image_ids) {
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) {
    throw std::runtime_error("cannot open " + path);
  }
  sqlite3_stmt* stmt = nullptr;
  if (sqlite3_prepare_v2(db, "SELECT image_id, rows, cols, data FROM descriptors ORDER BY image_id",
                         -1, &stmt, nullptr) != SQLITE_OK) {
    sqlite3_close(db);
    throw std::runtime_error("no descriptors table in " + path);
  }
  std::vector<FeatureDescriptors> images;
  while (images.size() < max_images && sqlite3_step(stmt) == SQLITE_ROW) {
    const int64_t rows = sqlite3_column_int64(stmt, 1);
    const int64_t cols = sqlite3_column_int64(stmt, 2);
    const int bytes = sqlite3_column_bytes(stmt, 3);
    if (cols != kDescriptorDim || bytes != rows * cols) {
      throw std::runtime_error("image " + std::to_string(sqlite3_column_int64(stmt, 0)) +
                               ": descriptors are not uint8 x 128");
    }
    FeatureDescriptors descriptors;
    const auto* blob = static_cast<const uint8_t*>(sqlite3_column_blob(stmt, 3));
    descriptors.data.assign(blob, blob + bytes);
    images.push_back(std::move(descriptors));
    image_ids->push_back(sqlite3_column_int64(stmt, 0));
  }
  sqlite3_finalize(stmt);
  sqlite3_close(db);
  return images;
}

struct Setting {
  int tables, bits, tau, top_k;
  bool automatic;
};

// "auto" settings get the shape ChooseTableShape gives `features`.
std::vector<Setting> ParseSettings(const std::string& text, size_t features) {
  std::vector<Setting> settings;
  std::stringstream all(text);
  std::string item;
  while (std::getline(all, item, ';')) {
    Setting s{};
    if (item.rfind("auto", 0) == 0) {
      const CasHashOptions defaults = CascadeOptions();
      s.tau = defaults.tau;
      s.top_k = defaults.top_k;
      if (item != "auto" && std::sscanf(item.c_str(), "auto,%d,%d", &s.tau, &s.top_k) != 2) {
        throw std::invalid_argument("bad setting '" + item + "' (want auto or auto,tau,top_k)");
      }
      const TableShape shape = ChooseTableShape(features);
      s.tables = shape.num_tables;
      s.bits = shape.bits_per_table;
      s.automatic = true;
    } else if (std::sscanf(item.c_str(), "%d,%d,%d,%d", &s.tables, &s.bits, &s.tau, &s.top_k) != 4) {
      throw std::invalid_argument("bad setting '" + item + "' (want tables,bits,tau,top_k)");
    }
    settings.push_back(s);
  }
  return settings;
}

size_t CountCommon(const FeatureMatches& a, const FeatureMatches& b) {
  // Both sorted by (idx1, idx2).
  size_t common = 0;
  for (size_t i = 0, j = 0; i < a.size() && j < b.size();) {
    if (a[i] == b[j]) {
      ++common, ++i, ++j;
    } else if (a[i] < b[j]) {
      ++i;
    } else {
      ++j;
    }
  }
  return common;
}

}  // namespace

int main(int argc, char** argv) {
  std::string database = "sceaux_castle.db";  // --database: any COLMAP feature database
  size_t max_pairs = static_cast<size_t>(-1);
  size_t max_images = static_cast<size_t>(-1);
  int threads = 1;
  uint64_t seed = 0;
  std::string settings_text = "6,8,48,10;6,10,48,10;8,10,48,10;8,10,48,5;10,10,48,10;8,12,48,10";
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    const std::string value = argv[i + 1];
    if (flag == "--database") database = value;
    else if (flag == "--max_pairs") max_pairs = std::stoul(value);
    else if (flag == "--max_images") max_images = std::stoul(value);
    else if (flag == "--threads") threads = std::stoi(value);
    else if (flag == "--seed") seed = std::stoull(value);
    else if (flag == "--settings") settings_text = value;
    else {
      std::fprintf(stderr, "unknown flag %s\n", flag.c_str());
      return 2;
    }
  }
  std::string command_line = argv[0];
  for (int i = 1; i < argc; ++i) command_line += std::string(" ") + argv[i];

  std::vector<int64_t> image_ids;
  const std::vector<FeatureDescriptors> images = ReadAllDescriptors(database, max_images, &image_ids);
  std::vector<const FeatureDescriptors*> pointers;
  size_t total_features = 0;
  for (const auto& image : images) {
    pointers.push_back(&image);
    total_features += image.rows();
  }
  const MeanDescriptor mean = ComputeMeanDescriptor(pointers);
  std::vector<std::pair<size_t, size_t>> pairs;
  for (size_t a = 0; a < images.size(); ++a) {
    for (size_t b = a + 1; b < images.size() && pairs.size() < max_pairs; ++b) pairs.push_back({a, b});
  }
  const SiftMatchingOptions sift;  // COLMAP defaults: ratio 0.8, distance 0.7, cross check
  const int num_threads = static_cast<int>(NumParallelWorkers(pairs.size(), threads));

  std::printf("# %s\n", command_line.c_str());
  std::printf("# %zu images, %.0f features per image, %zu pairs, %d thread(s)\n\n", images.size(),
              images.empty() ? 0.0 : double(total_features) / images.size(), pairs.size(), num_threads);

  // Exact reference.
  std::vector<WideDescriptors> wide;
  for (const auto& image : images) wide.push_back(WidenDescriptors(image, image.rows()));
  std::vector<FeatureMatches> exact(pairs.size());
  double start = CpuSeconds();
  ParallelFor(pairs.size(), num_threads, [&](size_t p) {
    exact[p] = BruteForceMatchPair(wide[pairs[p].first], wide[pairs[p].second], sift);
  });
  const double brute_seconds = CpuSeconds() - start;
  size_t exact_total = 0;
  for (const auto& m : exact) exact_total += m.size();
  std::printf("brute force: %zu matches, %.3f CPU s, %.2f pairs per CPU second\n\n", exact_total, brute_seconds,
              pairs.size() / brute_seconds);

  // Where the database already holds COLMAP's raw matches (a COLMAP CPU
  // matching run with default options), the brute force must equal them.
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(database.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK) {
    size_t compared = 0, identical = 0;
    for (size_t p = 0; p < pairs.size(); ++p) {
      FeatureMatches colmap;
      if (!ReadColmapMatches(db, image_ids[pairs[p].first], image_ids[pairs[p].second], &colmap)) continue;
      ++compared;
      identical += colmap == exact[p];
      if (colmap != exact[p]) {
        std::printf("pair %lld-%lld: COLMAP %zu matches, ours %zu, %zu in common\n",
                    (long long)image_ids[pairs[p].first], (long long)image_ids[pairs[p].second],
                    colmap.size(), exact[p].size(), CountCommon(colmap, exact[p]));
      }
    }
    if (compared > 0) {
      std::printf("COLMAP's stored matches: %zu pairs compared, %zu identical to our brute force\n\n",
                  compared, identical);
    }
  }
  sqlite3_close(db);

  std::vector<size_t> rows;
  for (const auto& image : images) rows.push_back(image.rows());
  const size_t median_features = TypicalFeatureCount(rows, sift.max_num_matches);
  {
    const TableShape shape = ChooseTableShape(median_features);
    std::printf("median %zu features per image: auto shape %d x %d\n\n", median_features, shape.num_tables,
                shape.bits_per_table);
  }
  std::printf("| tables x bits | tau | top_k | recall | min pair recall | precision | "
              "bucket entries | within tau | ranked | hash CPU ms/image | pairs per CPU s | speed-up |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Setting& s : ParseSettings(settings_text, median_features)) {
    CasHashOptions options = CascadeOptions();
    options.num_tables = s.tables;
    options.bits_per_table = s.bits;
    options.tau = s.tau;
    options.top_k = s.top_k;
    options.random_seed = seed;
    const CascadeProjections projections = GenerateCascadeProjections(options);
    start = CpuSeconds();
    std::vector<CascadeImage> hashed(images.size());
    ParallelFor(images.size(), num_threads, [&](size_t i) {
      hashed[i] = BuildCascadeImage(images[i], images[i].rows(), projections, mean);
    });
    const double hash_seconds = CpuSeconds() - start;

    std::vector<FeatureMatches> cascade(pairs.size());
    std::vector<CascadeStats> stats(pairs.size());
    std::vector<CascadeScratch> scratch(num_threads);
    start = CpuSeconds();
    ParallelForWorkers(pairs.size(), num_threads, [&](size_t p, size_t worker) {
      cascade[p] = CascadeMatchPair(hashed[pairs[p].first], hashed[pairs[p].second], sift, options,
                                    &scratch[worker], &stats[p]);
    });
    const double cascade_seconds = CpuSeconds() - start;

    CascadeStats total;
    size_t common = 0, found = 0;
    double min_recall = 1.0;
    for (size_t p = 0; p < pairs.size(); ++p) {
      total.Add(stats[p]);
      const size_t c = CountCommon(exact[p], cascade[p]);
      common += c;
      found += cascade[p].size();
      // Pairs with few exact matches do not overlap; their recall is noise.
      if (exact[p].size() >= 100) min_recall = std::min(min_recall, double(c) / exact[p].size());
    }
    const double queries = std::max<double>(1.0, total.num_queries);
    std::printf("| %s%d x %d | %d | %d | %.4f | %.4f | %.4f | %.1f | %.1f | %.2f | %.1f | %.1f | %.1f |\n",
                s.automatic ? "auto: " : "", s.tables, s.bits, s.tau, s.top_k, exact_total ? double(common) / exact_total : 1.0,
                min_recall, found ? double(common) / found : 1.0, total.bucket_entries / queries,
                total.within_tau / queries, total.ranked / queries,
                1000.0 * hash_seconds / std::max<size_t>(1, images.size()),
                pairs.size() / cascade_seconds, brute_seconds / cascade_seconds);
    std::fflush(stdout);
  }
  return 0;
}
