// Rows per second of the database writer (DatabaseResultSink) with and
// without --write_empty_pairs, on a copy of a feature database such as one
// from `cashash generate_database`. Matching and verification are left out:
// every pair gets a made-up result shaped like the street scene's, where an
// image pairs with its `--neighbours` nearest images on each side (matches
// falling with the distance, a calibrated geometry) and a share
// `--far_with_matches` of the other pairs gets a few chance matches and a
// degenerate geometry (the cascade matcher leaves almost every far pair
// with some, brute force about half). Pairs are
// written in ExhaustiveMatching blocks, one transaction per block pair,
// as the pipeline writes them.
//
// Usage: write_rows_bench DATABASE SCRATCH_DIR [--block_size 50]
//        [--neighbours 10] [--far_with_matches 0.0] [--matches 2000]
#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "cashash/pipeline/pair_generation.h"
#include "cashash/geometry/random_sampler.h"
#include "colmap_bridge/database.h"
#include "colmap_bridge/database_pipeline_io.h"

namespace {

using namespace cashash;
using namespace cashash::colmap;

struct BenchOptions {
  int block_size = 50;
  int neighbours = 10;
  double far_with_matches = 0.0;
  int matches = 2000;  // raw matches of the nearest pair
};

FeatureMatches MakeMatches(size_t count, SplitMix64& rng) {
  FeatureMatches matches(count);
  for (size_t k = 0; k < count; ++k) {
    matches[k].point2D_idx1 = rng.Below(8192);
    matches[k].point2D_idx2 = rng.Below(8192);
  }
  return matches;
}

PairResult MakeResult(const ImagePair& pair, size_t distance, const BenchOptions& o, SplitMix64& rng) {
  PairResult result;
  result.pair = pair;
  if (distance <= static_cast<size_t>(o.neighbours)) {
    const double share = 1.0 - static_cast<double>(distance) / (o.neighbours + 1);
    result.matches = MakeMatches(static_cast<size_t>(o.matches * share), rng);
    result.geometry.config = kCalibrated;
    result.geometry.F = Eigen::Matrix3d::Random();
    result.geometry.E = Eigen::Matrix3d::Random();
    result.geometry.qvec = Eigen::Vector4d(0.99, 0.01, 0.1, 0.0).normalized();
    result.geometry.tvec = Eigen::Vector3d(1, 0, 0.05);
    result.geometry.inlier_matches.assign(result.matches.begin(),
                                          result.matches.begin() + static_cast<long>(result.matches.size() * 9 / 10));
  } else if (rng.Next() % 1000000 < static_cast<uint64_t>(o.far_with_matches * 1000000)) {
    result.matches = MakeMatches(1 + rng.Below(14), rng);
    result.geometry.config = kDegenerate;
  } else {
    result.geometry.config = kDegenerate;  // matched, nothing found
  }
  return result;
}

struct Measurement {
  double write_seconds = 0;
  double close_seconds = 0;  // the writer's last checkpoint, when it closes
  size_t pairs = 0;
  size_t rows = 0;
  size_t empty_recorded = 0;
  double resume_read_seconds = 0;
  size_t resume_pairs = 0;
  double megabytes_added = 0;
  double log_megabytes = 0;  // the -wal file at its largest (SQLite never shrinks it)
};

Measurement Run(const std::string& source, const std::string& copy, bool write_empty_pairs, const BenchOptions& o) {
  std::filesystem::remove(copy);
  std::filesystem::copy_file(source, copy);
  const double bytes_before = static_cast<double>(std::filesystem::file_size(copy));
  std::vector<image_t> image_ids;
  std::unordered_map<image_t, size_t> position;
  {
    Database db(copy, /*read_only=*/true);
    for (const Image& image : db.ReadAllImages()) {
      position[image.image_id] = image_ids.size();
      image_ids.push_back(image.image_id);
    }
  }
  const std::vector<PairChunk> chunks = ExhaustivePairChunks(image_ids, o.block_size);
  Measurement m;
  SplitMix64 rng(7);
  {
    auto sink =
        std::make_unique<DatabaseResultSink>(copy, DatabaseResultSink::Options{true, write_empty_pairs, false});
    for (const PairChunk& chunk : chunks) {
      std::vector<PairResult> results;
      results.reserve(chunk.pairs.size());
      for (const ImagePair& pair : chunk.pairs) {
        const size_t a = position[pair.first], b = position[pair.second];
        results.push_back(MakeResult(pair, a > b ? a - b : b - a, o, rng));
      }
      const auto t0 = std::chrono::steady_clock::now();
      sink->WriteChunk(results);
      m.write_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      m.pairs += results.size();
    }
    m.rows = sink->rows_written();
    m.empty_recorded = sink->empty_pairs_recorded();
    std::error_code no_log;
    m.log_megabytes = static_cast<double>(std::filesystem::file_size(copy + "-wal", no_log)) / (1024.0 * 1024.0);
    if (no_log) m.log_megabytes = 0;
    const auto t0 = std::chrono::steady_clock::now();
    sink.reset();  // folds the WAL into the file: part of what writing costs
    m.close_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  {
    const auto t0 = std::chrono::steady_clock::now();
    Database db(copy, /*read_only=*/true);
    m.resume_pairs = db.ReadCompletedPairIds().size();
    m.resume_read_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  // The WAL is folded into the file when the last connection closes.
  m.megabytes_added = (static_cast<double>(std::filesystem::file_size(copy)) - bytes_before) / (1024.0 * 1024.0);
  std::filesystem::remove(copy);
  return m;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::cerr << "usage: " << argv[0]
              << " DATABASE SCRATCH_DIR [--block_size 50] [--neighbours 10] [--far_with_matches 0.0] [--matches 2000]\n";
    return 2;
  }
  BenchOptions o;
  for (int i = 3; i + 1 < argc; i += 2) {
    const std::string name = argv[i];
    if (name == "--block_size") o.block_size = std::atoi(argv[i + 1]);
    else if (name == "--neighbours") o.neighbours = std::atoi(argv[i + 1]);
    else if (name == "--far_with_matches") o.far_with_matches = std::atof(argv[i + 1]);
    else if (name == "--matches") o.matches = std::atoi(argv[i + 1]);
    else {
      std::cerr << "unknown option " << name << "\n";
      return 2;
    }
  }
  const std::string copy = (std::filesystem::path(argv[2]) / "write_rows_bench.db").string();
  std::cout << "| write_empty_pairs | pairs | rows written | empty pairs recorded | write s | close s | pairs/s | rows/s | "
               "MiB added | log MiB at most | resume read s |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (bool write_empty : {true, false}) {
    const Measurement m = Run(argv[1], copy, write_empty, o);
    std::cout << std::fixed << "| " << (write_empty ? 1 : 0) << " | " << m.pairs << " | " << m.rows << " | "
              << m.empty_recorded << " | " << std::setprecision(2) << m.write_seconds << " | " << m.close_seconds << " | "
              << std::setprecision(0) << m.pairs / (m.write_seconds + m.close_seconds) << " | "
              << m.rows / (m.write_seconds + m.close_seconds) << " | " << std::setprecision(1)
              << m.megabytes_added << " | " << m.log_megabytes << " | " << std::setprecision(3) << m.resume_read_seconds << " (" << m.resume_pairs
              << " pairs) |" << std::endl;
  }
  return 0;
}
