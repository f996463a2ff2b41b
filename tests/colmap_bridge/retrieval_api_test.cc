// MatchRetrieval (cashash retrieval_matcher) on a small generated street:
// the next image along the street is among each image's most similar, the
// retrieved pairs and only they are matched, the neighbours verify, a rerun
// resumes, the transitive step adds pairs, and bad options are refused.
#include "colmap_bridge/api/retrieval_api.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <set>
#include <stdexcept>

#include "cashash/base/pair_id.h"
#include "colmap_bridge/database.h"
#include "generated_database_support.h"
#include "synthetic/database_generator.h"

namespace cashash {
namespace colmap {
namespace {

using testing_support::ScratchDir;
using testing_support::WriteRandomSourceDatabase;

constexpr int kImages = 24;

std::string GenerateStreetDatabase(const ScratchDir& dir) {
  const std::string source = dir.File("source.db");
  WriteRandomSourceDatabase(source, 4, 2000);
  DatabaseGeneratorOptions options;
  options.database_path = dir.File("street.db");
  options.source_database_path = source;
  options.num_images = kImages;
  options.num_features = 512;
  options.random_seed = 4;
  GenerateDatabase(options);
  return options.database_path;
}

MatcherCommandOptions CpuOptions(int num_images) {
  MatcherCommandOptions options;
  options.use_gpu = false;
  options.retrieval.num_images = num_images;
  return options;
}

TEST(MatchRetrieval, MatchesExactlyTheRetrievedPairs) {
  const ScratchDir dir("retrieval_api");
  const std::string path = GenerateStreetDatabase(dir);

  // Retrieval alone: each image's nearest neighbours along the street are
  // among its most similar images.
  RetrievalOptions retrieval;
  retrieval.num_images = 4;
  const DatabaseRetrievalIndex index = BuildDatabaseRetrievalIndex(path, retrieval);
  ASSERT_EQ(index.image_ids.size(), static_cast<size_t>(kImages));
  const RetrievedPairs retrieved = RetrievePairs(index, retrieval);
  std::set<pair_t> chosen;
  for (const ImagePair& p : retrieved.pairs) {
    EXPECT_LT(p.first, p.second);
    chosen.insert(ImagePairToPairId(p.first, p.second));
  }
  EXPECT_LE(retrieved.pairs.size(), static_cast<size_t>(kImages * 4));
  for (image_t id = 1; id < kImages; ++id) {
    EXPECT_TRUE(chosen.count(ImagePairToPairId(id, id + 1))) << "images " << id << " and " << id + 1;
  }

  // The matcher writes exactly the retrieved pairs, and verifies the
  // neighbours.
  const MatchingSummary summary = MatchRetrieval(path, CpuOptions(4));
  EXPECT_EQ(summary.pairs_requested, retrieved.pairs.size());
  EXPECT_EQ(summary.pipeline.pairs_done, retrieved.pairs.size());
  {
    const Database database(path, /*read_only=*/true);
    EXPECT_EQ(database.ReadCompletedPairIds(), std::unordered_set<pair_t>(chosen.begin(), chosen.end()));
    for (image_t id = 1; id < kImages; ++id) {
      EXPECT_GE(database.ReadTwoViewGeometry(id, id + 1).inlier_matches.size(), 15u) << "images " << id;
    }
  }
  // A rerun resumes: everything is already there.
  const MatchingSummary again = MatchRetrieval(path, CpuOptions(4));
  EXPECT_EQ(again.pairs_skipped, again.pairs_requested);
  EXPECT_EQ(again.pipeline.pairs_done, 0u);

  // The transitive step adds pairs implied by the verified graph, never
  // one that was already tried.
  MatcherCommandOptions transitive = CpuOptions(4);
  transitive.transitive_rounds = 1;
  const MatchingSummary closed = MatchRetrieval(path, transitive);
  EXPECT_GT(closed.pipeline.pairs_done, 0u);
  const Database database(path, /*read_only=*/true);
  EXPECT_GT(database.ReadCompletedPairIds().size(), chosen.size());
}

TEST(MatchRetrieval, RefusesBadOptionsNamingThem) {
  const ScratchDir dir("retrieval_api_options");
  MatcherCommandOptions options = CpuOptions(0);
  try {
    MatchRetrieval(dir.File("missing.db"), options);
    FAIL() << "num_images 0 was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("VocabTreeMatching.num_images"), std::string::npos);
  }
  options = CpuOptions(5);
  options.transitive_rounds = -1;
  EXPECT_THROW(MatchRetrieval(dir.File("missing.db"), options), std::invalid_argument);
}

}  // namespace
}  // namespace colmap
}  // namespace cashash
