// The writer hands the folding of SQLite's write-ahead log to a thread of its
// own (WalCheckpointer): every committed row must still be there, readers
// must see each chunk as soon as it is committed, the log must not grow
// without bound, and a database without a log must be written as before.
#include <gtest/gtest.h>

#include <sqlite3.h>

#include <filesystem>
#include <string>
#include <vector>

#include "cashash/base/pair_id.h"
#include "colmap_bridge/colmap38_schema.h"
#include "colmap_bridge/database.h"
#include "colmap_bridge/database_pipeline_io.h"
#include "colmap_bridge/wal_checkpointer.h"
#include "generated_database_support.h"

namespace cashash {
namespace {

using colmap::Database;
using colmap::DatabaseResultSink;

std::string QueryText(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr);
  sqlite3_stmt* s = nullptr;
  std::string value = "(no row)";
  if (sqlite3_prepare_v2(db, sql.c_str(), -1, &s, nullptr) == SQLITE_OK && sqlite3_step(s) == SQLITE_ROW) {
    value = reinterpret_cast<const char*>(sqlite3_column_text(s, 0));
  }
  sqlite3_finalize(s);
  sqlite3_close(db);
  return value;
}

// Pairs (first, first + 1 .. first + count) with `num_matches` matches each and
// an uncalibrated geometry keeping half of them: about 3 pages per pair.
std::vector<PairResult> MakeChunk(image_t first, int count, int num_matches) {
  std::vector<PairResult> results;
  for (int k = 1; k <= count; ++k) {
    PairResult r;
    r.pair = {first, first + static_cast<image_t>(k)};
    for (int m = 0; m < num_matches; ++m) {
      r.matches.push_back({static_cast<point2D_t>(m), static_cast<point2D_t>((m * 7 + k) % 4096)});
    }
    r.geometry.config = kUncalibrated;
    r.geometry.F = Eigen::Matrix3d::Identity();
    r.geometry.inlier_matches.assign(r.matches.begin(), r.matches.begin() + num_matches / 2);
    results.push_back(std::move(r));
  }
  return results;
}

class WalCheckpointerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    colmap::CreateColmap38Database(path_);
    colmap::SetWalJournal(path_);  // as COLMAP's own databases
  }

  uintmax_t LogBytes() const {
    std::error_code none;
    const uintmax_t bytes = std::filesystem::file_size(path_ + "-wal", none);
    return none ? 0 : bytes;
  }

  testing_support::ScratchDir scratch_{"wal_checkpointer_test"};
  std::string path_ = scratch_.File("db.db");
};

TEST_F(WalCheckpointerTest, EveryChunkIsReadableAtOnceAndAllRowsSurviveClosing) {
  constexpr int kChunks = 60;
  constexpr int kPairs = 8;
  {
    DatabaseResultSink::Options options;
    options.log_pages_before_catch_up = 32;
    options.commit_seconds = 0;  // a commit per chunk, each folded under the reader
    DatabaseResultSink sink(path_, options);
    Database reader(path_, /*read_only=*/true);
    for (int c = 0; c < kChunks; ++c) {
      const image_t first = static_cast<image_t>(1 + c * (kPairs + 1));
      const std::vector<PairResult> chunk = MakeChunk(first, kPairs, 800);
      sink.WriteChunk(chunk);
      // Another connection sees the chunk as soon as it is committed, while
      // the checkpointer may be folding the log under it.
      const FeatureMatches back = reader.ReadMatches(first, first + kPairs);
      ASSERT_EQ(back.size(), chunk.back().matches.size()) << "chunk " << c;
      EXPECT_EQ(back[17].point2D_idx2, chunk.back().matches[17].point2D_idx2);
      EXPECT_EQ(reader.ReadTwoViewGeometry(first, first + 1).inlier_matches.size(), 400u);
    }
    EXPECT_EQ(sink.rows_written(), static_cast<size_t>(2 * kChunks * kPairs));
  }
  // The last connection folded the log and removed it, as SQLite does.
  EXPECT_FALSE(std::filesystem::exists(path_ + "-wal"));
  EXPECT_EQ(QueryText(path_, "SELECT COUNT(*) FROM matches WHERE rows = 800"), std::to_string(kChunks * kPairs));
  EXPECT_EQ(QueryText(path_, "SELECT COUNT(*) FROM two_view_geometries WHERE rows = 400"),
            std::to_string(kChunks * kPairs));
  EXPECT_EQ(QueryText(path_, "PRAGMA integrity_check"), "ok");
}

TEST_F(WalCheckpointerTest, TheLogStartsOverInsteadOfGrowing) {
  // 60 chunks of about 25 pages each: some 1,500 pages (6 MiB) in all. With a
  // bound of 32 pages the log must stay within the bound plus about a chunk.
  DatabaseResultSink::Options options;
  options.log_pages_before_catch_up = 32;
  options.commit_seconds = 0;  // a commit per chunk
  DatabaseResultSink sink(path_, options);
  uintmax_t largest = 0;
  for (int c = 0; c < 60; ++c) {
    sink.WriteChunk(MakeChunk(static_cast<image_t>(1 + c * 9), 8, 800));
    largest = std::max(largest, LogBytes());
  }
  constexpr uintmax_t kPageWithHeader = 4096 + 24;
  EXPECT_GT(largest, 0u) << "COLMAP's schema keeps a write-ahead log";
  EXPECT_LT(largest, 4 * 32 * kPageWithHeader) << "the log was never started over";
}

TEST_F(WalCheckpointerTest, CatchUpLeavesNothingToFold) {
  Database writer(path_);
  int logged = -1;
  writer.HandOverLogFolding([&](int pages) { logged = pages; });
  colmap::WalCheckpointer checkpointer(path_);
  writer.BeginTransaction();
  for (const PairResult& r : MakeChunk(1, 20, 500)) writer.WriteMatches(r.pair.first, r.pair.second, r.matches);
  writer.Commit();
  EXPECT_GT(logged, 20) << "the hook reports the log's pages after each commit";
  checkpointer.CatchUp();
  EXPECT_GE(checkpointer.checkpoints(), 1u);

  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open_v2(path_.c_str(), &db, SQLITE_OPEN_READWRITE, nullptr), SQLITE_OK);
  sqlite3_exec(db, "SELECT COUNT(*) FROM matches", nullptr, nullptr, nullptr);
  int in_log = -1, folded = -1;
  EXPECT_EQ(sqlite3_wal_checkpoint_v2(db, nullptr, SQLITE_CHECKPOINT_PASSIVE, &in_log, &folded), SQLITE_OK);
  sqlite3_close(db);
  EXPECT_EQ(in_log, logged);
  EXPECT_EQ(folded, in_log) << "pages left in the log after CatchUp()";
}

TEST_F(WalCheckpointerTest, ADatabaseWithoutALogIsWrittenAsBefore) {
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open(path_.c_str(), &db), SQLITE_OK);
    ASSERT_EQ(sqlite3_exec(db, "PRAGMA journal_mode = DELETE", nullptr, nullptr, nullptr), SQLITE_OK);
    sqlite3_close(db);
  }
  {
    DatabaseResultSink sink(path_, DatabaseResultSink::Options{});
    for (int c = 0; c < 5; ++c) sink.WriteChunk(MakeChunk(static_cast<image_t>(1 + c * 9), 8, 100));
  }
  EXPECT_EQ(QueryText(path_, "PRAGMA journal_mode"), "delete");
  EXPECT_EQ(QueryText(path_, "SELECT COUNT(*) FROM matches"), "40");
  EXPECT_FALSE(std::filesystem::exists(path_ + "-wal"));
}

}  // namespace
}  // namespace cashash
