// Bookkeeping of large runs: the resume set is one bit per pair of the run
// (CompletedPairs), completed pairs are streamed from the database, and a
// finished run leaves the database without -wal and -shm files.
#include <gtest/gtest.h>

#include <filesystem>
#include <random>
#include <set>

#include <sqlite3.h>

#include "cashash/pipeline/pair_generation.h"
#include "cashash/base/pair_id.h"
#include "colmap_bridge/completed_pairs.h"
#include "colmap_bridge/database.h"
#include "synthetic/database_generator.h"
#include "colmap_bridge/api/matching_api.h"
#include "colmap_bridge/commands/verify_command.h"
#include "generated_database_support.h"

namespace cashash {
namespace {

using colmap::CompletedPairs;

std::vector<image_t> Ids(image_t first, int count, image_t step = 1) {
  std::vector<image_t> ids;
  for (int k = 0; k < count; ++k) ids.push_back(first + static_cast<image_t>(k) * step);
  return ids;
}

// Marks a random third of the run's pairs plus pairs outside the run, then
// asks about every pair of the run.
void ExpectMarksAreKept(const std::vector<image_t>& ids, const std::vector<PairChunk>& chunks) {
  CompletedPairs completed(ids, chunks);
  std::mt19937 rng(3);
  std::set<pair_t> marked;
  for (const PairChunk& chunk : chunks) {
    for (const ImagePair& pair : chunk.pairs) {
      if (rng() % 3 == 0) {
        const pair_t id = ImagePairToPairId(pair.first, pair.second);
        completed.Mark(id);
        completed.Mark(id);  // twice: counted once
        marked.insert(id);
      }
    }
  }
  // Not pairs of the run: an image the run does not have, an image with itself.
  completed.Mark(ImagePairToPairId(ids.back() + 1000, ids.front()));
  completed.Mark(ImagePairToPairId(ids.front(), ids.front()));
  EXPECT_EQ(completed.num_completed(), marked.size());
  size_t checked = 0;
  for (const PairChunk& chunk : chunks) {
    for (const ImagePair& pair : chunk.pairs) {
      const bool expected = marked.count(ImagePairToPairId(pair.first, pair.second)) > 0;
      EXPECT_EQ(completed.Contains(pair.first, pair.second), expected) << pair.first << " " << pair.second;
      EXPECT_EQ(completed.Contains(pair.second, pair.first), expected);
      ++checked;
    }
  }
  EXPECT_GT(checked, 0u);
  EXPECT_FALSE(completed.Contains(ids.back() + 1000, ids.front()));
}

TEST(CompletedPairsTest, ExhaustiveRunUsesOneBitPerPair) {
  const std::vector<image_t> ids = Ids(1, 101);
  const std::vector<PairChunk> chunks = ScheduledPairChunks(ids, 7, 3);
  CompletedPairs completed(ids, chunks);
  EXPECT_TRUE(completed.uses_image_triangle());
  ExpectMarksAreKept(ids, chunks);
}

TEST(CompletedPairsTest, SparseImageIdsAndPairListsWork) {
  // Ids far apart: looked up through a map instead of a dense table.
  const std::vector<image_t> sparse = Ids(5, 40, 100000);
  ExpectMarksAreKept(sparse, ScheduledPairChunks(sparse, 6, 2));
  // A chain over many images: the list of its pairs is smaller than the triangle.
  const std::vector<image_t> ids = Ids(1, 400);
  std::vector<ImagePair> chain;
  for (size_t k = 0; k + 1 < ids.size(); ++k) chain.emplace_back(ids[k + 1], ids[k]);
  const std::vector<PairChunk> chunks = ListPairChunks(chain, 25, 10);
  EXPECT_FALSE(CompletedPairs(ids, chunks).uses_image_triangle());
  ExpectMarksAreKept(ids, chunks);
}

TEST(CompletedPairsTest, MemoryIsTheBitsOfTheRun) {
  // 3000 images, 4.5 million pairs: a set of pair ids took ~200 MB here.
  const std::vector<image_t> ids = Ids(1, 3000);
  const std::vector<PairChunk> chunks = ScheduledPairChunks(ids, 50, 10);
  CompletedPairs completed(ids, chunks);
  for (const PairChunk& chunk : chunks) {
    for (const ImagePair& pair : chunk.pairs) completed.Mark(ImagePairToPairId(pair.first, pair.second));
  }
  const size_t n = ids.size();
  EXPECT_EQ(completed.num_completed(), n * (n - 1) / 2);
  EXPECT_LE(completed.memory_bytes(), n * (n - 1) / 16 + 8 + 4 * (n + 1));
}

TEST(CompletedPairsTest, ExhaustiveRunHoldsNoBitsUntilAPairIsCompleted) {
  // A fresh run at 20,000 images would otherwise fill 25 MiB of zeros.
  const std::vector<image_t> ids = Ids(1, 3000);
  const size_t n = ids.size();
  CompletedPairs completed(ids);
  EXPECT_TRUE(completed.uses_image_triangle());
  EXPECT_LE(completed.memory_bytes(), 4 * (n + 1));  // the image index alone
  EXPECT_FALSE(completed.Contains(ids[3], ids[7]));
  completed.Mark(ImagePairToPairId(ids[7], ids[3]));
  completed.Mark(ImagePairToPairId(ids.back() + 1, ids[3]));  // not an image of the run
  EXPECT_EQ(completed.num_completed(), 1u);
  EXPECT_TRUE(completed.Contains(ids[3], ids[7]));
  // The bits by positions, as ScheduledChunkSource reads them.
  const PairTriangle bits = completed.TakeTriangle();
  EXPECT_EQ(bits.size(), n);
  EXPECT_EQ(bits.count(), 1u);
  EXPECT_TRUE(bits.Test(3, 7));
  EXPECT_FALSE(bits.Test(3, 8));
}

size_t CountFiles(const std::string& path) {
  size_t count = 0;
  for (const char* suffix : {"-wal", "-shm", "-journal"}) count += std::filesystem::exists(path + suffix) ? 1 : 0;
  return count;
}

class FinishedRunTest : public ::testing::Test {
 protected:
  void SetUp() override {
    testing_support::WriteRandomSourceDatabase(scratch_.File("source.db"), 2, 800);
    colmap::DatabaseGeneratorOptions o;
    o.database_path = path_;
    o.source_database_path = scratch_.File("source.db");
    o.num_images = 14;
    o.num_features = 256;
    colmap::GenerateDatabase(o);
    options_.use_gpu = false;
    options_.skip_geometric_verification = true;  // fast; the files are what matters
    options_.two_view.max_num_trials = 500;
  }

  std::string JournalMode() {
    sqlite3* db = nullptr;
    // Read-write: a read-only connection closing last would itself leave the files.
    sqlite3_open_v2(path_.c_str(), &db, SQLITE_OPEN_READWRITE, nullptr);
    sqlite3_stmt* s = nullptr;
    std::string mode;
    if (sqlite3_prepare_v2(db, "PRAGMA journal_mode", -1, &s, nullptr) == SQLITE_OK && sqlite3_step(s) == SQLITE_ROW) {
      mode = reinterpret_cast<const char*>(sqlite3_column_text(s, 0));
    }
    sqlite3_finalize(s);
    sqlite3_close(db);
    return mode;
  }

  testing_support::ScratchDir scratch_{"large_run_bookkeeping_test"};
  std::string path_ = scratch_.File("db.db");
  colmap::MatcherCommandOptions options_;
};

TEST_F(FinishedRunTest, LeavesOnlyTheDatabaseFile) {
  ASSERT_EQ(JournalMode(), "wal");  // COLMAP's mode, kept by the generator
  ASSERT_EQ(CountFiles(path_), 0u);
  const colmap::MatchingSummary first = colmap::MatchExhaustive(path_, options_);
  EXPECT_EQ(first.pipeline.pairs_done, 91u);
  EXPECT_EQ(CountFiles(path_), 0u) << "after an exhaustive run";
  // A rerun with nothing left to do opens the reader only.
  const colmap::MatchingSummary again = colmap::MatchExhaustive(path_, options_);
  EXPECT_EQ(again.pairs_skipped, 0u);  // no geometries: matched again
  options_.skip_geometric_verification = false;
  options_.sift.num_threads = 2;
  colmap::MatchPairs(path_, {{"synthetic_000001.jpg", "synthetic_000002.jpg"}}, options_);
  EXPECT_EQ(CountFiles(path_), 0u) << "after a pair list";
  colmap::VerifyExistingMatches(path_, options_);
  EXPECT_EQ(CountFiles(path_), 0u) << "after geometric verification";
  const colmap::MatchingSummary nothing = colmap::VerifyExistingMatches(path_, options_);
  EXPECT_EQ(nothing.pairs_skipped, 91u);
  EXPECT_EQ(CountFiles(path_), 0u) << "after a run with nothing to do";
  EXPECT_EQ(JournalMode(), "wal");
}

TEST_F(FinishedRunTest, ReadersCannotWrite) {
  colmap::Database reader(path_, /*read_only=*/true);
  EXPECT_THROW(reader.ClearMatchesAndGeometries(), colmap::DatabaseError);
  colmap::Database writer(path_);
  writer.WriteMatches(1, 2, FeatureMatches{{0, 1}});
  // Streamed by the reader: a pair counts once it has both rows.
  EXPECT_TRUE(reader.ReadCompletedPairIds().empty());
  writer.WriteTwoViewGeometry(1, 2, TwoViewGeometry());
  writer.WriteTwoViewGeometry(3, 4, TwoViewGeometry());
  writer.RecordEmptyPairs({ImagePairToPairId(5, 6), ImagePairToPairId(5, 7)});
  EXPECT_EQ(reader.ReadCompletedPairIds(),
            (std::unordered_set<pair_t>{ImagePairToPairId(1, 2), ImagePairToPairId(5, 6), ImagePairToPairId(5, 7)}));
}

}  // namespace
}  // namespace cashash
