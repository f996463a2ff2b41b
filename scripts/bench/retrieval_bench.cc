// Time and recall of image retrieval from the hash codes (docs/retrieval.md)
// on a COLMAP database, without matching anything:
//
//   retrieval_bench --database DB [--num_images K] [--num_tables T]
//       [--bits_per_word B] [--num_nearest_neighbors P]
//       [--max_num_features M] [--threads N] [--seed S]
//       [--truth EXHAUSTIVE_DB] [--min_inliers 15] [--strong_inliers 50]
//       [--pairs_out FILE]
//
// Prints the wall time of each phase (mean descriptor; reading and hashing
// every image; building the inverted file; querying every image), the
// postings the queries read and the pairs chosen. With --truth (a copy of
// DB matched exhaustively), also the share of the pairs verified there
// with at least --strong_inliers and at least --min_inliers inliers that
// retrieval chose (matching the chosen pairs verifies the same pairs: the
// matcher and verifier see each pair alone). --pairs_out writes the pairs
// as a matches_importer list.
#include <sqlite3.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <set>
#include <stdexcept>
#include <string>

#include "cashash/base/pair_id.h"
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

}  // namespace

int main(int argc, char** argv) {
  std::string database, truth, pairs_out;
  RetrievalOptions options;
  options.num_images = 50;
  int min_inliers = 15, strong_inliers = 50;
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
    else if (key == "--min_inliers") min_inliers = std::stoi(value);
    else if (key == "--strong_inliers") strong_inliers = std::stoi(value);
    else {
      std::fprintf(stderr, "unknown option %s\n", key.c_str());
      return 1;
    }
  }
  if (database.empty()) {
    std::fprintf(stderr, "usage: retrieval_bench --database DB [--truth EXHAUSTIVE_DB] [options]\n");
    return 1;
  }
  try {
    const colmap::DatabaseRetrievalIndex index = colmap::BuildDatabaseRetrievalIndex(database, options);
    const colmap::RetrievedPairs retrieved = colmap::RetrievePairs(index, options);
    const size_t n = index.image_ids.size();
    const double all_pairs = 0.5 * static_cast<double>(n) * static_cast<double>(n - 1);
    std::printf("images %zu, features %zu, %d tables x %d bits, %d words per feature and table per query\n", n,
                index.features_indexed, options.num_tables, index.bits_per_word, options.num_nearest_neighbors);
    std::printf("seconds: mean %.3f, reading+hashing %.3f, indexing %.3f, querying %.3f, total %.3f\n",
                index.seconds_mean, index.seconds_reading_and_hashing, index.seconds_indexing,
                retrieved.seconds_querying,
                index.seconds_mean + index.seconds_reading_and_hashing + index.seconds_indexing +
                    retrieved.seconds_querying);
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
