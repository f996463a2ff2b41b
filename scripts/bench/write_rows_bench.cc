// The database writer (DatabaseResultSink) alone, in the order a real
// exhaustive run writes: ScheduledPairChunks, one WriteChunk per block pair,
// a Flush at the end, then closing (the last checkpoint). Matching and
// verification are left out, so the writer has the machine to itself.
//
// The rows are either those of a finished run (--rows_from RUN_DB: every
// pair's matches and two_view_geometries rows, read back before timing; the
// rows written are then checked to be the same), or made up: an image pairs
// with its `--neighbours` nearest images on each side (`--matches` raw
// matches for the nearest, falling with the distance, 90 % of them inliers
// of a calibrated geometry) and a share `--far_with_matches` of the other
// pairs gets a few chance matches (many matches per row: the blobs of
// 8,192-feature images).
//
// Each round writes with every writer setting below on its own fresh copy,
// then SQLite inserts the same rows into another copy with INSERT ... SELECT
// in pair-id order (the floor). Prints every round and the medians.
//   per chunk    one transaction per chunk, SQLite's 2 MiB page cache: how
//                the writer committed before it grouped chunks
//   1 s, no MiB bound  grouped by time alone (commit_mib 0)
//   default      DatabaseResultSink::Options' defaults
//   sync NORMAL  the defaults with DiskSync::kNormal (see DiskSync's risk)
//
// Usage: write_rows_bench DATABASE SCRATCH_DIR [--rows_from RUN_DB] [--block_size 50]
//        [--blocks_per_group 0 (all)] [--rounds 3] [--neighbours 10] [--far_with_matches 0.0]
//        [--matches 2000]
#include <sqlite3.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "cashash/geometry/random_sampler.h"
#include "cashash/pipeline/pair_generation.h"
#include "colmap_bridge/database.h"
#include "colmap_bridge/database_pipeline_io.h"

namespace {

using namespace cashash;
using namespace cashash::colmap;

struct BenchOptions {
  std::string rows_from;
  int block_size = 50;
  int blocks_per_group = 0;
  int rounds = 3;
  int neighbours = 10;
  double far_with_matches = 0.0;
  int matches = 2000;  // raw matches of the nearest pair
};

struct Setting {
  std::string name;
  DatabaseResultSink::Options options;
};

std::vector<Setting> Settings() {
  DatabaseResultSink::Options per_chunk;
  per_chunk.commit_seconds = 0;
  per_chunk.cache_mib = 0;
  DatabaseResultSink::Options time_only;
  time_only.commit_mib = 0;
  DatabaseResultSink::Options normal;
  normal.disk_sync = DiskSync::kNormal;
  return {{"per chunk", per_chunk},
          {"1 s, no MiB bound", time_only},
          {"default", DatabaseResultSink::Options()},
          {"sync NORMAL", normal}};
}

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

// Every chunk's results, made before any timing.
std::vector<std::vector<PairResult>> MakeChunkResults(const std::string& database, const BenchOptions& o) {
  std::vector<image_t> image_ids;
  std::unordered_map<image_t, size_t> position;
  {
    Database db(database, /*read_only=*/true);
    for (const Image& image : db.ReadAllImages()) {
      position[image.image_id] = image_ids.size();
      image_ids.push_back(image.image_id);
    }
  }
  const int num_blocks = static_cast<int>((image_ids.size() + o.block_size - 1) / o.block_size);
  const std::vector<PairChunk> chunks =
      ScheduledPairChunks(image_ids, o.block_size, o.blocks_per_group > 0 ? o.blocks_per_group : num_blocks);
  std::unique_ptr<Database> rows;
  if (!o.rows_from.empty()) rows = std::make_unique<Database>(o.rows_from, /*read_only=*/true);
  SplitMix64 rng(7);
  std::vector<std::vector<PairResult>> results(chunks.size());
  for (size_t c = 0; c < chunks.size(); ++c) {
    results[c].reserve(chunks[c].pairs.size());
    for (const ImagePair& pair : chunks[c].pairs) {
      if (rows) {
        PairResult result;
        result.pair = pair;
        result.matches = rows->ReadMatches(pair.first, pair.second);
        result.geometry = rows->ReadTwoViewGeometry(pair.first, pair.second);
        results[c].push_back(std::move(result));
      } else {
        const size_t a = position[pair.first], b = position[pair.second];
        results[c].push_back(MakeResult(pair, a > b ? a - b : b - a, o, rng));
      }
    }
  }
  return results;
}

double ThreadCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// Bytes this process has handed to write(2) and pwrite(2) so far.
double WrittenMegabytes() {
  std::ifstream io("/proc/self/io");
  std::string key;
  double value = 0;
  while (io >> key >> value) {
    if (key == "wchar:") return value / (1024.0 * 1024.0);
  }
  return 0;
}

void FreshCopy(const std::string& source, const std::string& copy) {
  for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(copy + suffix);
  std::filesystem::copy_file(source, copy);
}

void Exec(sqlite3* db, const std::string& sql) {
  char* message = nullptr;
  if (sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &message) != SQLITE_OK) {
    const std::string text = message != nullptr ? message : "?";
    sqlite3_free(message);
    throw std::runtime_error(sql + ": " + text);
  }
}

int64_t QueryInt(sqlite3* db, const std::string& sql) {
  sqlite3_stmt* s = nullptr;
  if (sqlite3_prepare_v2(db, sql.c_str(), -1, &s, nullptr) != SQLITE_OK) throw std::runtime_error(sql);
  const int64_t value = sqlite3_step(s) == SQLITE_ROW ? sqlite3_column_int64(s, 0) : -1;
  sqlite3_finalize(s);
  return value;
}

// Rows of `table` in one database and not the other, both ways.
int64_t RowsDiffering(const std::string& a, const std::string& b, const std::string& table) {
  sqlite3* db = nullptr;
  sqlite3_open_v2(a.c_str(), &db, SQLITE_OPEN_READWRITE, nullptr);
  Exec(db, "ATTACH DATABASE '" + b + "' AS other");
  const int64_t n = QueryInt(db, "SELECT (SELECT count(*) FROM (SELECT * FROM main." + table + " EXCEPT SELECT * FROM other." +
                                     table + ")) + (SELECT count(*) FROM (SELECT * FROM other." + table +
                                     " EXCEPT SELECT * FROM main." + table + "))");
  sqlite3_close_v2(db);
  return n;
}

// INSERT ... SELECT of the rows of `written` into `target`, in pair-id order,
// one transaction; seconds from BEGIN to the end of COMMIT.
double SqliteInsertSelect(const std::string& written, const std::string& target) {
  sqlite3* db = nullptr;
  sqlite3_open_v2(target.c_str(), &db, SQLITE_OPEN_READWRITE, nullptr);
  Exec(db, "ATTACH DATABASE '" + written + "' AS run");
  const auto t0 = std::chrono::steady_clock::now();
  Exec(db, "BEGIN IMMEDIATE");
  Exec(db, "INSERT INTO main.matches SELECT * FROM run.matches ORDER BY pair_id");
  Exec(db, "INSERT INTO main.two_view_geometries SELECT * FROM run.two_view_geometries ORDER BY pair_id");
  Exec(db, "COMMIT");
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  sqlite3_close_v2(db);
  return seconds;
}

struct Measurement {
  double write_seconds = 0;  // WriteChunk calls and the final Flush
  double close_seconds = 0;  // the writer's last checkpoint, when it closes
  double cpu_seconds = 0;    // of this thread while writing
  double written_megabytes = 0;  // write(2) bytes while writing and closing, checkpoints included
  size_t rows = 0;
  size_t commits = 0;
  double sqlite_seconds = 0;  // INSERT ... SELECT of the same rows
  int64_t rows_differing = -1;
};

Measurement Run(const std::string& source, const std::string& scratch, const Setting& setting,
                const std::vector<std::vector<PairResult>>& chunks, const BenchOptions& o) {
  const std::string copy = scratch + "/write_rows_bench.db";
  FreshCopy(source, copy);
  Measurement m;
  const double megabytes_before = WrittenMegabytes();
  {
    auto sink = std::make_unique<DatabaseResultSink>(copy, setting.options);
    const double cpu0 = ThreadCpuSeconds();
    const auto t0 = std::chrono::steady_clock::now();
    for (const std::vector<PairResult>& results : chunks) sink->WriteChunk(results);
    sink->Flush();
    m.write_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    m.cpu_seconds = ThreadCpuSeconds() - cpu0;
    m.rows = sink->rows_written();
    m.commits = sink->commits();
    const auto t1 = std::chrono::steady_clock::now();
    sink.reset();
    m.close_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
  }
  m.written_megabytes = WrittenMegabytes() - megabytes_before;
  if (!o.rows_from.empty()) {
    m.rows_differing = RowsDiffering(copy, o.rows_from, "matches") + RowsDiffering(copy, o.rows_from, "two_view_geometries");
  }
  const std::string floor = scratch + "/write_rows_bench_floor.db";
  FreshCopy(source, floor);
  m.sqlite_seconds = SqliteInsertSelect(copy, floor);
  for (const std::string& path : {copy, floor}) {
    for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path + suffix);
  }
  return m;
}

double Median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  const size_t n = values.size();
  return n % 2 == 1 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::cerr << "usage: " << argv[0]
              << " DATABASE SCRATCH_DIR [--rows_from RUN_DB] [--block_size 50] [--blocks_per_group 0] [--rounds 3]"
                 " [--neighbours 10] [--far_with_matches 0.0] [--matches 2000]\n";
    return 2;
  }
  BenchOptions o;
  for (int i = 3; i + 1 < argc; i += 2) {
    const std::string name = argv[i];
    if (name == "--rows_from") o.rows_from = argv[i + 1];
    else if (name == "--block_size") o.block_size = std::atoi(argv[i + 1]);
    else if (name == "--blocks_per_group") o.blocks_per_group = std::atoi(argv[i + 1]);
    else if (name == "--rounds") o.rounds = std::max(1, std::atoi(argv[i + 1]));
    else if (name == "--neighbours") o.neighbours = std::atoi(argv[i + 1]);
    else if (name == "--far_with_matches") o.far_with_matches = std::atof(argv[i + 1]);
    else if (name == "--matches") o.matches = std::atoi(argv[i + 1]);
    else {
      std::cerr << "unknown option " << name << "\n";
      return 2;
    }
  }
  try {
    const auto chunks = MakeChunkResults(argv[1], o);
    size_t pairs = 0;
    for (const auto& c : chunks) pairs += c.size();
    std::cout << chunks.size() << " chunks, " << pairs << " pairs, block size " << o.block_size << std::endl;
    const std::vector<Setting> settings = Settings();
    std::map<std::string, std::vector<Measurement>> all;
    std::cout << std::fixed << std::setprecision(2);
    for (int round = 0; round < o.rounds; ++round) {
      for (const Setting& setting : settings) {
        const Measurement m = Run(argv[1], argv[2], setting, chunks, o);
        all[setting.name].push_back(m);
        std::cout << "round " << round + 1 << ", " << setting.name << ": write " << m.write_seconds << " s, close "
                  << m.close_seconds << " s, CPU " << m.cpu_seconds << " s, " << m.commits << " commits, "
                  << m.written_megabytes << " MiB written; INSERT ... SELECT " << m.sqlite_seconds << " s"
                  << (m.rows_differing >= 0 ? ", rows differing from --rows_from: " + std::to_string(m.rows_differing) : "")
                  << std::endl;
      }
    }
    std::cout << "\n| setting | rows | commits | write s | close s | writer CPU s | MiB written | rows/s | "
                 "INSERT ... SELECT s | write / SQLite |\n|---|---|---|---|---|---|---|---|---|---|\n";
    for (const Setting& setting : settings) {
      const std::vector<Measurement>& ms = all[setting.name];
      std::vector<double> write, close, cpu, mib, sqlite, ratio;
      for (const Measurement& m : ms) {
        write.push_back(m.write_seconds);
        close.push_back(m.close_seconds);
        cpu.push_back(m.cpu_seconds);
        mib.push_back(m.written_megabytes);
        sqlite.push_back(m.sqlite_seconds);
        ratio.push_back(m.write_seconds / m.sqlite_seconds);
      }
      std::cout << "| " << setting.name << " | " << ms[0].rows << " | " << ms[0].commits << " | " << Median(write)
                << " | " << Median(close) << " | " << Median(cpu) << " | " << std::setprecision(0) << Median(mib)
                << " | " << ms[0].rows / Median(write) << " | " << std::setprecision(2) << Median(sqlite) << " | "
                << Median(ratio) << " |" << std::endl;
    }
  } catch (const std::exception& e) {
    std::cerr << "ERROR: " << e.what() << std::endl;
    return 1;
  }
  return 0;
}
