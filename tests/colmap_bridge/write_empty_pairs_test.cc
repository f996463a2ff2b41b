// --write_empty_pairs: 1 writes rows for every matched pair as COLMAP does,
// 0 only for pairs with matches and records the others so that a rerun
// skips them; the record's encoding round-trips and rejects damage.
#include <gtest/gtest.h>

#include "cashash/base/pair_id.h"
#include "colmap_bridge/database.h"
#include "synthetic/database_generator.h"
#include "colmap_bridge/database_pipeline_io.h"
#include "colmap_bridge/api/matching_api.h"
#include "colmap_bridge/pair_id_runs.h"
#include "database_queries.h"
#include "generated_database_support.h"

namespace cashash {
namespace {

using colmap::Database;
using testing_support::QueryInt;

// Pairs of image 1 with its near neighbours (matches) and with far images
// (no match: the street scene shares no point, descriptors are unrelated).
std::vector<std::pair<std::string, std::string>> NearAndFarPairs() {
  std::vector<std::pair<std::string, std::string>> pairs;
  for (int j : {2, 3, 20, 21, 22, 23, 24, 25}) {
    char name[32];
    std::snprintf(name, sizeof(name), "synthetic_%06d.jpg", j);
    pairs.emplace_back("synthetic_000001.jpg", name);
  }
  return pairs;
}

class WriteEmptyPairsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    testing_support::WriteRandomSourceDatabase(scratch_.File("source.db"), 2, 1500);
    colmap::DatabaseGeneratorOptions o;
    o.database_path = path_;
    o.source_database_path = scratch_.File("source.db");
    o.num_images = 25;
    o.num_features = 512;
    colmap::GenerateDatabase(o);
    options_.use_gpu = false;
    options_.cashash.matcher = MatcherType::kBruteForce;
  }

  testing_support::ScratchDir scratch_{"write_empty_pairs_test"};
  std::string path_ = scratch_.File("db.db");
  colmap::MatcherCommandOptions options_;
};

TEST_F(WriteEmptyPairsTest, OnWritesEveryPairAsColmapDoes) {
  const colmap::MatchingSummary summary = colmap::MatchPairs(path_, NearAndFarPairs(), options_);
  EXPECT_EQ(summary.pipeline.pairs_done, 8u);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM matches"), 8);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM two_view_geometries"), 8);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM matches WHERE rows = 0"), 6);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM sqlite_master WHERE name = 'cashash_empty_pairs'"), 0);
}

TEST_F(WriteEmptyPairsTest, OffWritesPairsWithMatchesOnlyAndResumeSkipsTheOthers) {
  options_.write_empty_pairs = false;
  colmap::MatchPairs(path_, NearAndFarPairs(), options_);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM matches"), 2);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM two_view_geometries"), 2);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM matches WHERE rows = 0"), 0);
  EXPECT_EQ(QueryInt(path_, "SELECT SUM(num_pairs) FROM cashash_empty_pairs"), 6);
  {
    Database db(path_, true);
    EXPECT_EQ(db.ReadCompletedPairIds().size(), 8u);
    EXPECT_EQ(db.ReadTwoViewGeometry(1, 2).config, kCalibrated);
  }
  // A rerun decides nothing again, whichever setting it runs with.
  EXPECT_EQ(colmap::MatchPairs(path_, NearAndFarPairs(), options_).pairs_skipped, 8u);
  options_.write_empty_pairs = true;
  EXPECT_EQ(colmap::MatchPairs(path_, NearAndFarPairs(), options_).pairs_skipped, 8u);
  // --overwrite forgets the record with the rows (exhaustive) or rewrites
  // the listed pairs, empty ones now with rows.
  options_.overwrite = true;
  colmap::MatchPairs(path_, NearAndFarPairs(), options_);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM matches"), 8);
}

TEST_F(WriteEmptyPairsTest, OverwriteWithoutEmptyRowsDeletesRowsOfPairsNowEmpty) {
  {
    colmap::DatabaseResultSink sink(path_, true);
    PairResult result;
    result.pair = {1, 25};
    result.matches = {{0, 0}, {1, 1}};
    sink.WriteChunk({result});
  }
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM matches"), 1);
  colmap::DatabaseResultSink sink(path_, colmap::DatabaseResultSink::Options{true, false, true});
  PairResult empty;
  empty.pair = {25, 1};
  sink.WriteChunk({empty});
  sink.Flush();
  EXPECT_EQ(sink.rows_written(), 0u);
  EXPECT_EQ(sink.empty_pairs_recorded(), 1u);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM matches"), 0);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM two_view_geometries"), 0);
  Database db(path_, true);
  EXPECT_EQ(db.ReadCompletedPairIds().count(ImagePairToPairId(1, 25)), 1u);
}

// --overwrite 1 with --skip_geometric_verification 1 rewrites the matches
// of its pairs; their old two_view_geometries rows would describe other
// matches and make a resumed run take the pairs as done. They go, so the
// next verifying run matches and verifies those pairs again.
TEST_F(WriteEmptyPairsTest, OverwriteWithoutVerificationDropsTheOldGeometries) {
  colmap::MatchPairs(path_, NearAndFarPairs(), options_);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM two_view_geometries"), 8);
  colmap::MatcherCommandOptions rewrite = options_;
  rewrite.overwrite = true;
  rewrite.skip_geometric_verification = true;
  const colmap::MatchingSummary rewritten = colmap::MatchPairs(path_, NearAndFarPairs(), rewrite);
  EXPECT_EQ(rewritten.pipeline.pairs_done, 8u);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM matches"), 8);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM two_view_geometries"), 0);
  const colmap::MatchingSummary resumed = colmap::MatchPairs(path_, NearAndFarPairs(), options_);
  EXPECT_EQ(resumed.pairs_skipped, 0u);
  EXPECT_EQ(resumed.pipeline.pairs_done, 8u);
  EXPECT_EQ(QueryInt(path_, "SELECT COUNT(*) FROM two_view_geometries"), 8);
}

TEST(PairIdRunsTest, RoundTripsRunsAndRejectsDamage) {
  const std::vector<pair_t> ids = {ImagePairToPairId(3, 9), 5, 6, 7, 1, 5, ImagePairToPairId(3, 10), 0};
  const std::vector<uint8_t> blob = colmap::EncodePairIdRuns(ids);
  std::vector<std::pair<pair_t, pair_t>> runs;
  colmap::DecodePairIdRuns(blob.data(), blob.size(), "test",
                           [&](pair_t first, pair_t last) { runs.emplace_back(first, last); });
  const std::vector<std::pair<pair_t, pair_t>> expected = {
      {0, 1}, {5, 7}, {ImagePairToPairId(3, 9), ImagePairToPairId(3, 10)}};
  EXPECT_EQ(runs, expected);
  // 2,500 consecutive ids (one image against a block) take two bytes each way.
  std::vector<pair_t> block;
  for (image_t j = 100; j < 2600; ++j) block.push_back(ImagePairToPairId(7, j));
  EXPECT_LE(colmap::EncodePairIdRuns(block).size(), 12u);

  std::vector<uint8_t> truncated(blob.begin(), blob.end() - 1);
  EXPECT_THROW(colmap::DecodePairIdRuns(truncated.data(), truncated.size(), "test", [](pair_t, pair_t) {}),
               colmap::DatabaseError);
  const uint8_t zero_length[] = {0x01, 0x00};
  EXPECT_THROW(colmap::DecodePairIdRuns(zero_length, sizeof(zero_length), "test", [](pair_t, pair_t) {}),
               colmap::DatabaseError);
}

}  // namespace
}  // namespace cashash
