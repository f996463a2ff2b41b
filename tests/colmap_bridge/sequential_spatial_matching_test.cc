// sequential_matcher and spatial_matcher through the library (MatchSequential,
// MatchSpatial) on a small generated street: the pairs written are COLMAP's,
// reruns resume, loop detection goes through an ImageRetrieval (the
// caller's, or the run's own from the hash codes), and missing priors are
// named.
#include <algorithm>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "cashash/base/pair_id.h"
#include "colmap_bridge/api/matching_api.h"
#include "colmap_bridge/sqlite_statement.h"
#include "generated_database_support.h"
#include "pair_id_sets.h"
#include "synthetic/database_generator.h"

namespace cashash {
namespace colmap {
namespace {

using testing_support::WithinSteps;

// Images 1..kImages, ids in name order.
constexpr int kImages = 16;

std::set<pair_t> StoredPairs(const std::string& path) {
  const Database db(path, /*read_only=*/true);
  const std::unordered_set<pair_t> ids = db.ReadCompletedPairIds();
  return std::set<pair_t>(ids.begin(), ids.end());
}

// Answers every query with the images of the far end of the street.
class FarEndRetrieval : public ImageRetrieval {
 public:
  std::vector<std::vector<image_t>> MostSimilarImages(const std::vector<image_t>& queries, int num_images) override {
    asked_for = num_images;
    std::vector<std::vector<image_t>> result;
    for (image_t query : queries) {
      queried.push_back(query);
      result.push_back({static_cast<image_t>(kImages), static_cast<image_t>(kImages - 1)});
    }
    return result;
  }
  std::vector<image_t> queried;
  int asked_for = 0;
};

class GeneratedStreet : public testing::Test {
 protected:
  void SetUp() override {
    testing_support::WriteRandomSourceDatabase(dir_.File("source.db"), 2, 400);
    DatabaseGeneratorOptions generator;
    generator.database_path = dir_.File("street.db");
    generator.source_database_path = dir_.File("source.db");
    generator.num_images = kImages;
    generator.num_features = 200;
    generator.position_priors = "cartesian";
    generator.num_threads = 1;
    GenerateDatabase(generator);
    path_ = generator.database_path;
    options_.use_gpu = false;
    options_.sift.num_threads = 1;
    options_.spatial.is_gps = false;  // the street's Cartesian priors in 3.8's columns
    callbacks_.warning = [this](const std::string& text) { warnings_.push_back(text); };
    callbacks_.info = [](const std::string&) {};
  }

  testing_support::ScratchDir dir_{"sequential_spatial"};
  std::string path_;
  MatcherCommandOptions options_;
  MatchingCallbacks callbacks_;
  std::vector<std::string> warnings_;
};

TEST_F(GeneratedStreet, SequentialWritesTheOverlapPairsAndResumes) {
  options_.sequential.overlap = 3;
  options_.sequential.quadratic_overlap = false;
  const MatchingSummary first = MatchSequential(path_, options_, callbacks_);
  EXPECT_EQ(first.pairs_requested, WithinSteps(kImages, 3).size());
  EXPECT_EQ(first.pipeline.pairs_done, WithinSteps(kImages, 3).size());
  EXPECT_GT(first.pipeline.verified_pairs, 0u);
  EXPECT_EQ(StoredPairs(path_), WithinSteps(kImages, 3));
  const MatchingSummary second = MatchSequential(path_, options_, callbacks_);
  EXPECT_EQ(second.pairs_skipped, WithinSteps(kImages, 3).size());
  EXPECT_EQ(second.pipeline.pairs_done, 0u);
  EXPECT_TRUE(warnings_.empty()) << testing::PrintToString(warnings_);
}

TEST_F(GeneratedStreet, LoopDetectionAsksTheRetrievalAndAddsItsPairs) {
  options_.sequential.overlap = 1;
  options_.sequential.quadratic_overlap = false;
  options_.sequential.loop_detection = true;
  options_.sequential.loop_detection_period = 5;
  options_.sequential.loop_detection_num_images = 2;
  FarEndRetrieval retrieval;
  MatchSequential(path_, options_, callbacks_, &retrieval);
  EXPECT_EQ(retrieval.queried, (std::vector<image_t>{1, 6, 11, 16}));
  EXPECT_EQ(retrieval.asked_for, 2);
  std::set<pair_t> expected = WithinSteps(kImages, 1);
  for (image_t query : {1, 6, 11}) {
    expected.insert(ImagePairToPairId(query, kImages));
    expected.insert(ImagePairToPairId(query, kImages - 1));
  }
  expected.insert(ImagePairToPairId(kImages, kImages - 1));
  EXPECT_EQ(StoredPairs(path_), expected);
}

TEST_F(GeneratedStreet, LoopDetectionRetrievesOverlappingImagesBeyondTheOverlap) {
  // The street's images overlap some ten places along it; the sequential
  // pairs reach two. Every image asks the retrieval from the database's
  // own descriptors, and only images at least three places away count.
  options_.sequential.overlap = 2;
  options_.sequential.quadratic_overlap = false;
  options_.sequential.loop_detection = true;
  options_.sequential.loop_detection_period = 1;
  options_.sequential.loop_detection_num_images = 2;
  options_.sequential.loop_detection_min_index_distance = 3;
  options_.sequential.num_threads = 1;
  const MatchingSummary summary = MatchSequential(path_, options_, callbacks_);
  const std::set<pair_t> stored = StoredPairs(path_);
  const std::set<pair_t> overlap = WithinSteps(kImages, 2);
  EXPECT_TRUE(std::includes(stored.begin(), stored.end(), overlap.begin(), overlap.end()));
  EXPECT_GT(stored.size(), overlap.size());
  EXPECT_EQ(summary.pairs_requested, stored.size());
  // Loop pairs that verify: images that truly overlap, found by retrieval.
  size_t verified_loops = 0;
  const Database db(path_, /*read_only=*/true);
  db.UseStatement("SELECT pair_id FROM two_view_geometries WHERE rows >= 15", [&](SqliteStatement& s) {
    while (s.Step()) {
      const auto [image1, image2] = PairIdToImagePair(static_cast<pair_t>(s.ColumnInt64(0)));
      if (image2 > image1 + 2) ++verified_loops;
    }
  });
  EXPECT_GT(verified_loops, 0u);
  EXPECT_TRUE(warnings_.empty()) << testing::PrintToString(warnings_);
}

TEST_F(GeneratedStreet, SpatialMatchesNeighboursWithinMaxDistance) {
  // Cameras stand one unit apart (0.15 of jitter along, 0.3 across the
  // street): two steps are within 2.5, three are not.
  options_.spatial.max_distance = 2.5;
  const MatchingSummary summary = MatchSpatial(path_, options_, callbacks_);
  EXPECT_EQ(summary.pairs_requested, WithinSteps(kImages, 2).size());
  EXPECT_EQ(StoredPairs(path_), WithinSteps(kImages, 2));
  EXPECT_TRUE(warnings_.empty()) << testing::PrintToString(warnings_);
}

TEST_F(GeneratedStreet, SpatialNamesImagesWithoutPriorAndFailsWithoutAny) {
  {
    Database db(path_);
    db.UseStatement("UPDATE images SET prior_tx = NULL, prior_ty = NULL WHERE name = 'synthetic_000004.jpg'",
                    [](SqliteStatement& s) { s.Execute(); });
  }
  options_.spatial.max_distance = 1.5;
  MatchSpatial(path_, options_, callbacks_);
  ASSERT_EQ(warnings_.size(), 1u);
  EXPECT_NE(warnings_[0].find("synthetic_000004.jpg"), std::string::npos) << warnings_[0];
  EXPECT_NE(warnings_[0].find("1 of the 16 images has no position prior"), std::string::npos) << warnings_[0];
  std::set<pair_t> expected = WithinSteps(kImages, 1);
  expected.erase(ImagePairToPairId(3, 4));
  expected.erase(ImagePairToPairId(4, 5));
  EXPECT_EQ(StoredPairs(path_), expected);
  {
    Database db(path_);
    db.UseStatement("UPDATE images SET prior_tx = NULL, prior_ty = NULL, prior_tz = NULL",
                    [](SqliteStatement& s) { s.Execute(); });
  }
  try {
    MatchSpatial(path_, options_, callbacks_);
    ADD_FAILURE() << "spatial matching ran without priors";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find("has a usable position prior"), std::string::npos) << error.what();
  }
}

TEST_F(GeneratedStreet, PairingOptionsAreChecked) {
  options_.sequential.overlap = 0;
  EXPECT_THROW(MatchSequential(path_, options_, callbacks_), std::invalid_argument);
  options_.sequential = SequentialPairingOptions();
  options_.spatial.max_num_neighbors = 0;
  EXPECT_THROW(MatchSpatial(path_, options_, callbacks_), std::invalid_argument);
}

}  // namespace
}  // namespace colmap
}  // namespace cashash
