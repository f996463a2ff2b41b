// The writer's transactions and batched rows: DatabaseResultSink holds whole
// chunks in one transaction until it has been open commit_seconds, holds
// commit_mib of blobs or is flushed (another connection sees nothing before, everything after), and
// the rows it writes several to a statement are those of one statement per
// row, pairs stored swapped included, in both schemas' conventions.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <string>
#include <vector>

#include "cashash/base/pair_id.h"
#include "colmap_bridge/colmap38_schema.h"
#include "colmap_bridge/database.h"
#include "colmap_bridge/database_pipeline_io.h"
#include "database_queries.h"
#include "generated_database_support.h"

namespace cashash {
namespace {

using colmap::Database;
using colmap::DatabaseResultSink;
using testing_support::QueryInt;
using testing_support::RowsDiffering;

// `count` pairs of image `first` with the images after it; every third pair
// in the order opposite to storage, every fourth without matches, the others
// with a calibrated geometry (F, E, pose) or a planar one (H only).
std::vector<PairResult> MakeChunk(image_t first, int count) {
  std::vector<PairResult> results;
  for (int k = 1; k <= count; ++k) {
    PairResult r;
    const image_t other = first + static_cast<image_t>(k);
    r.pair = k % 3 == 0 ? ImagePair{other, first} : ImagePair{first, other};
    if (k % 4 != 0) {
      for (int m = 0; m < 10 + k; ++m) {
        r.matches.push_back({static_cast<point2D_t>(m), static_cast<point2D_t>((m * 7 + k) % 97)});
      }
      r.geometry.inlier_matches.assign(r.matches.begin(), r.matches.begin() + 8);
      if (k % 2 == 0) {
        r.geometry.config = kPlanar;
        r.geometry.H = Eigen::Matrix3d::Identity() * 1.5;
      } else {
        r.geometry.config = kCalibrated;
        r.geometry.F = Eigen::Matrix3d::Constant(0.25);
        r.geometry.E = Eigen::Matrix3d::Constant(-0.5);
        r.geometry.qvec = Eigen::Vector4d(0.9, 0.1, 0.3, 0.2).normalized();
        r.geometry.tvec = Eigen::Vector3d(1, 0.1, -0.2);
      }
    } else {
      r.geometry.config = kDegenerate;
    }
    results.push_back(std::move(r));
  }
  return results;
}

class WriterTransactionsTest : public ::testing::TestWithParam<bool> {
 protected:
  void SetUp() override {
    for (const std::string& path : {path_, reference_}) {
      colmap::CreateColmap38Database(path);
      colmap::SetWalJournal(path);
      // COLMAP 4.x's numbering: unset matrices and poses are written NULL.
      if (GetParam()) {
        sqlite3* db = nullptr;
        sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE, nullptr);
        sqlite3_exec(db, "PRAGMA user_version = 4020100", nullptr, nullptr, nullptr);
        sqlite3_close(db);
      }
    }
  }
  testing_support::ScratchDir scratch_{"writer_transactions_test"};
  std::string path_ = scratch_.File("db.db");
  std::string reference_ = scratch_.File("reference.db");
};

TEST_P(WriterTransactionsTest, ChunksWaitForTheCommitThenAllAppear) {
  DatabaseResultSink::Options options;
  options.commit_seconds = 3600;
  DatabaseResultSink sink(path_, options);
  sink.WriteChunk(MakeChunk(1, 100));
  sink.WriteChunk(MakeChunk(200, 100));
  EXPECT_EQ(QueryInt(path_, "SELECT count(*) FROM matches"), 0) << "another connection saw an open transaction";
  EXPECT_EQ(sink.commits(), 0u);
  EXPECT_EQ(sink.rows_written(), 0u) << "rows count once committed";
  sink.Flush();
  EXPECT_EQ(sink.commits(), 1u);
  EXPECT_EQ(sink.rows_written(), 400u);
  EXPECT_EQ(QueryInt(path_, "SELECT count(*) FROM matches"), 200);
  EXPECT_EQ(QueryInt(path_, "SELECT count(*) FROM two_view_geometries"), 200);
  sink.Flush();  // nothing open: no commit
  EXPECT_EQ(sink.commits(), 1u);
}

TEST_P(WriterTransactionsTest, ClosingCommitsWhatIsWritten) {
  {
    DatabaseResultSink::Options options;
    options.commit_seconds = 3600;
    DatabaseResultSink sink(path_, options);
    sink.WriteChunk(MakeChunk(1, 30));
  }
  EXPECT_EQ(QueryInt(path_, "SELECT count(*) FROM two_view_geometries"), 30);
}

TEST_P(WriterTransactionsTest, ZeroSecondsCommitsEveryChunk) {
  DatabaseResultSink::Options options;
  options.commit_seconds = 0;
  DatabaseResultSink sink(path_, options);
  sink.WriteChunk(MakeChunk(1, 10));
  EXPECT_EQ(QueryInt(path_, "SELECT count(*) FROM matches"), 10);
  sink.WriteChunk(MakeChunk(100, 10));
  EXPECT_EQ(QueryInt(path_, "SELECT count(*) FROM matches"), 20);
  EXPECT_EQ(sink.commits(), 2u);
}

// 20 pairs with 4,000 matches each (8 of them inliers): 0.6 MiB of blobs.
std::vector<PairResult> MakeLargeChunk(image_t first) {
  std::vector<PairResult> results;
  for (int k = 1; k <= 20; ++k) {
    PairResult r;
    r.pair = ImagePair{first, first + static_cast<image_t>(k)};
    for (int m = 0; m < 4000; ++m) r.matches.push_back({static_cast<point2D_t>(m), static_cast<point2D_t>(m)});
    r.geometry.inlier_matches.assign(r.matches.begin(), r.matches.begin() + 8);
    r.geometry.config = kCalibrated;
    results.push_back(std::move(r));
  }
  return results;
}

TEST_P(WriterTransactionsTest, ATransactionCommitsOnceItsBlobsReachCommitMib) {
  DatabaseResultSink::Options options;
  options.commit_seconds = 3600;
  options.commit_mib = 1;
  DatabaseResultSink sink(path_, options);
  sink.WriteChunk(MakeLargeChunk(1));
  EXPECT_EQ(sink.commits(), 0u) << "0.6 MiB is below the bound";
  sink.WriteChunk(MakeLargeChunk(100));
  EXPECT_EQ(sink.commits(), 1u) << "1.2 MiB reaches it";
  EXPECT_EQ(QueryInt(path_, "SELECT count(*) FROM matches"), 40);
  sink.WriteChunk(MakeLargeChunk(200));
  EXPECT_EQ(sink.commits(), 1u) << "the count starts over after a commit";
}

TEST_P(WriterTransactionsTest, ZeroCommitMibGroupsByTimeAlone) {
  DatabaseResultSink::Options options;
  options.commit_seconds = 3600;
  options.commit_mib = 0;
  DatabaseResultSink sink(path_, options);
  for (image_t first : {1, 100, 200}) sink.WriteChunk(MakeLargeChunk(first));
  EXPECT_EQ(sink.commits(), 0u);
  sink.Flush();
  EXPECT_EQ(QueryInt(path_, "SELECT count(*) FROM matches"), 60);
}

// 150 pairs a chunk: two statements of 64 rows and 22 single rows.
TEST_P(WriterTransactionsTest, BatchedRowsAreThoseOfOneStatementPerRow) {
  const std::vector<PairResult> first = MakeChunk(1, 150), second = MakeChunk(300, 7);
  {
    DatabaseResultSink sink(path_, true);
    sink.WriteChunk(first);
    sink.WriteChunk(second);
  }
  {
    Database db(reference_);
    db.BeginTransaction();
    for (const std::vector<PairResult>* chunk : {&first, &second}) {
      for (const PairResult& r : *chunk) {
        db.WriteMatches(r.pair.first, r.pair.second, r.matches);
        db.WriteTwoViewGeometry(r.pair.first, r.pair.second, r.geometry);
      }
    }
    db.Commit();
  }
  EXPECT_EQ(QueryInt(path_, "SELECT count(*) FROM matches"), 157);
  EXPECT_EQ(RowsDiffering(path_, reference_, "matches"), 0);
  EXPECT_EQ(RowsDiffering(path_, reference_, "two_view_geometries"), 0);
  // And they read back as written, swapped pairs included.
  Database db(path_, true);
  for (const PairResult& r : first) {
    EXPECT_EQ(db.ReadMatches(r.pair.first, r.pair.second), r.matches);
    EXPECT_EQ(db.ReadTwoViewGeometry(r.pair.first, r.pair.second).inlier_matches, r.geometry.inlier_matches);
  }
}

INSTANTIATE_TEST_SUITE_P(Schemas, WriterTransactionsTest, ::testing::Values(false, true),
                         [](const ::testing::TestParamInfo<bool>& info) {
                           return info.param ? "Colmap4x" : "Colmap38";
                         });

}  // namespace
}  // namespace cashash
