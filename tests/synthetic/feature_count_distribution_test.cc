// generate_database's feature counts: "equal" gives every image
// num_features; "extraction" puts about num_features_at_cap_share of the
// images at the cap and spreads the rest evenly below it, the same counts
// for a seed whatever else changes, and the database holds those counts.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "colmap_bridge/database.h"
#include "generated_database_support.h"
#include "synthetic/database_generator.h"

namespace cashash {
namespace {

using colmap::DatabaseGeneratorOptions;
using colmap::FeatureCountOfImage;

DatabaseGeneratorOptions Extraction(int cap, int low, double at_cap) {
  DatabaseGeneratorOptions o;
  o.num_features = cap;
  o.num_features_distribution = "extraction";
  o.min_num_features = low;
  o.num_features_at_cap_share = at_cap;
  o.random_seed = 11;
  return o;
}

TEST(FeatureCountDistribution, EqualGivesEveryImageNumFeatures) {
  DatabaseGeneratorOptions o;
  o.num_features = 4321;
  for (int k = 0; k < 100; ++k) EXPECT_EQ(FeatureCountOfImage(o, k), 4321);
}

TEST(FeatureCountDistribution, ExtractionStaysWithinBoundsWithItsShareAtTheCap) {
  const int cap = 12288, low = 1000, images = 20000;
  const DatabaseGeneratorOptions o = Extraction(cap, low, 0.4);
  int at_cap = 0, lower_half = 0;
  double sum = 0;
  for (int k = 0; k < images; ++k) {
    const int n = FeatureCountOfImage(o, k);
    ASSERT_GE(n, low);
    ASSERT_LE(n, cap);
    at_cap += n == cap;
    lower_half += n < (low + cap) / 2;
    sum += n;
  }
  EXPECT_NEAR(static_cast<double>(at_cap) / images, 0.4, 0.02);
  // Evenly below the cap: half of the 60 % below the middle.
  EXPECT_NEAR(static_cast<double>(lower_half) / images, 0.3, 0.02);
  // Mean 0.4 cap + 0.6 (low + cap) / 2.
  EXPECT_NEAR(sum / images, 0.4 * cap + 0.6 * (low + cap) / 2.0, 0.02 * cap);
}

TEST(FeatureCountDistribution, ExtractionIsFixedByTheSeedAlone) {
  DatabaseGeneratorOptions a = Extraction(8192, 500, 0.2);
  DatabaseGeneratorOptions b = a;
  b.num_images = 5000;
  b.num_threads = 3;
  b.distractor_ratio = 0.5;
  DatabaseGeneratorOptions c = a;
  c.random_seed = 12;
  int differ = 0;
  double sum = 0;
  for (int k = 0; k < 5000; ++k) {
    EXPECT_EQ(FeatureCountOfImage(a, k), FeatureCountOfImage(b, k));
    differ += FeatureCountOfImage(a, k) != FeatureCountOfImage(c, k);
    sum += FeatureCountOfImage(a, k);
  }
  EXPECT_GT(differ, 3000);
  // The scale benchmark's database: mean near 5,000 at a cap of 8,192.
  EXPECT_NEAR(sum / 5000, 5100, 150);
}

TEST(FeatureCountDistribution, DefaultFloorIsAnEighthOfTheCapAndEveryImageMayBeAtTheCap) {
  DatabaseGeneratorOptions o = Extraction(8000, 0, 0.0);
  int fewest = 8000;
  for (int k = 0; k < 5000; ++k) fewest = std::min(fewest, FeatureCountOfImage(o, k));
  EXPECT_GE(fewest, 1000);
  EXPECT_LT(fewest, 1100);
  o.num_features_at_cap_share = 1.0;
  for (int k = 0; k < 100; ++k) EXPECT_EQ(FeatureCountOfImage(o, k), 8000);
}

TEST(FeatureCountDistribution, TheDatabaseHoldsTheDrawnCounts) {
  testing_support::ScratchDir scratch("feature_count_test");
  const std::string source = scratch.File("source.db");
  testing_support::WriteRandomSourceDatabase(source, 3, 2000);
  DatabaseGeneratorOptions o = Extraction(600, 100, 0.3);
  o.database_path = scratch.File("out.db");
  o.source_database_path = source;
  o.num_images = 12;
  const colmap::GeneratorSummary summary = colmap::GenerateDatabase(o);
  colmap::Database db(o.database_path, true);
  int64_t total = 0;
  for (image_t id = 1; id <= 12; ++id) {
    const int n = FeatureCountOfImage(o, static_cast<int>(id) - 1);
    EXPECT_EQ(db.NumDescriptors(id), static_cast<size_t>(n)) << id;
    EXPECT_EQ(db.ReadKeypoints(id).size(), static_cast<size_t>(n)) << id;
    total += n;
  }
  EXPECT_EQ(summary.num_features, total);
  EXPECT_LT(summary.min_features, summary.max_features);
  // 70 % of every image's features are scene points, as at equal counts.
  EXPECT_NEAR(static_cast<double>(summary.observed_features) / summary.num_features, 0.7, 0.03);
}

TEST(FeatureCountDistribution, BadOptionsAreNamed) {
  DatabaseGeneratorOptions o = Extraction(1000, 100, 0.5);
  o.database_path = "out.db";
  o.source_database_path = "source.db";
  o.num_images = 3;
  EXPECT_EQ(o.Check(), "");
  o.num_features_distribution = "gaussian";
  EXPECT_NE(o.Check().find("--num_features_distribution"), std::string::npos);
  o = Extraction(1000, 2000, 0.5);
  o.database_path = "out.db";
  o.source_database_path = "source.db";
  o.num_images = 3;
  EXPECT_NE(o.Check().find("--min_num_features"), std::string::npos);
  o.min_num_features = 10;
  o.num_features_at_cap_share = 1.5;
  EXPECT_NE(o.Check().find("--num_features_at_cap_share"), std::string::npos);
}

}  // namespace
}  // namespace cashash
