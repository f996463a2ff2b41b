// The rule that chooses the hash tables from the features per image
// (table_shape.h): today's 8 x 7 at 8,192 features, one bit more per
// doubling while the GPU limits allow the collision probability to hold,
// tables chosen to keep it, explicit values kept.
#include "cashash/matching/table_shape.h"

#include <random>

#include <gtest/gtest.h>

#include <utility>
#include <vector>

#include "cashash/matchers/exact_matcher.h"
#include "synthetic_sift.h"
#include "cascade_options.h"

namespace cashash {
namespace {

TEST(TableShape, DefaultsAt8192FeaturesAreEightTablesOfSevenBits) {
  const TableShape shape = ChooseTableShape(8192);
  EXPECT_EQ(shape.num_tables, 8);
  EXPECT_EQ(shape.bits_per_table, 7);
  // 0 = size unknown: the same shape.
  EXPECT_EQ(ChooseTableShape(0).num_tables, 8);
  EXPECT_EQ(ChooseTableShape(0).bits_per_table, 7);
  // Between 8,192 and 16,383 features nothing changes (real SIFT images of
  // 10k-12.5k features keep the measured defaults).
  EXPECT_EQ(ChooseTableShape(12500).bits_per_table, 7);
  EXPECT_EQ(ChooseTableShape(16383).bits_per_table, 7);
}

TEST(TableShape, OneBitPerDoublingWithTablesKeepingTheCollisionProbability) {
  struct Expected {
    size_t features;
    int tables, bits;
  };
  for (const Expected& e : {Expected{100, 8, 7}, Expected{2048, 8, 7}, Expected{4096, 8, 7}, Expected{8192, 8, 7},
                            Expected{16384, 8, 8}, Expected{32768, 8, 8}, Expected{1 << 20, 8, 8}}) {
    const TableShape shape = ChooseTableShape(e.features);
    EXPECT_EQ(shape.num_tables, e.tables) << e.features;
    EXPECT_EQ(shape.bits_per_table, e.bits) << e.features;
  }
  const double target = TableCollisionProbability(8, 7);
  EXPECT_NEAR(target, 0.9746, 1e-3);
  // For fewer bits, the tables reach the target and one table fewer would
  // not: 6 x 5, 7 x 6, 8 x 7.
  for (int bits : {5, 6, 7}) {
    const int tables = TablesForBits(bits);
    EXPECT_EQ(tables, bits + 1);
    EXPECT_GE(TableCollisionProbability(tables, bits), target - 1e-12);
    EXPECT_LT(TableCollisionProbability(tables - 1, bits), target);
  }
  // 8 bits would need 10 tables (80 bits): capped at 64 / 8.
  EXPECT_EQ(TablesForBits(8), 8);
  EXPECT_EQ(TablesForBits(10), 6);
}

TEST(TableShape, CandidatesPerQueryStayAtMostTheDefaultsUpTo32768Features) {
  // Bucket entries a query visits: tables x features / 2^bits.
  auto entries = [](size_t features) {
    const TableShape s = ChooseTableShape(features);
    return static_cast<double>(s.num_tables) * static_cast<double>(features) / double(size_t{1} << s.bits_per_table);
  };
  const double reference = entries(8192);  // 8 x 8192 / 128 = 512
  EXPECT_DOUBLE_EQ(reference, 512.0);
  for (size_t features : {2048, 4096, 16384, 32768}) {
    EXPECT_LE(entries(features), 2.0 * reference) << features;
  }
  EXPECT_DOUBLE_EQ(entries(16384), reference);  // 8 x 16384 / 256
}

TEST(TableShape, OnTheCpuLargeImagesGetBucketsOfAboutFourFeatures) {
  const double reference = TableCollisionProbability(8, 7);
  auto cpu = [](size_t features, TableShapeGoal goal = TableShapeGoal::kRecall) {
    return ChooseTableShape(features, 0, 0, goal, TableShapeBackend::kCpu);
  };
  // 16,384 features: 19 x 12, 76 bucket entries a query against 8 x 8's 512.
  EXPECT_EQ(cpu(16384).num_tables, 19);
  EXPECT_EQ(cpu(16384).bits_per_table, 12);
  EXPECT_EQ(cpu(32768).num_tables, 22);
  EXPECT_EQ(cpu(32768).bits_per_table, 13);
  for (size_t features : {16384, 20000, 32768, 65536, 1 << 20}) {
    const TableShape shape = cpu(features);
    // The fewest tables that hold the reference's collision probability.
    EXPECT_GE(TableCollisionProbability(shape.num_tables, shape.bits_per_table), reference - 1e-12) << features;
    EXPECT_LT(TableCollisionProbability(shape.num_tables - 1, shape.bits_per_table), reference - 1e-12) << features;
    // Buckets of kCpuFineBucket to 2 kCpuFineBucket features.
    const double bucket = static_cast<double>(features) / double(size_t{1} << shape.bits_per_table);
    EXPECT_GE(bucket, kCpuFineBucket) << features;
    EXPECT_LT(bucket, 2.0 * kCpuFineBucket) << features;
  }
  // Below 16,384 features, for screening, or with tables or bits given, the
  // CPU takes the shapes the GPU can run.
  for (size_t features : {2048, 4096, 8192, 16383}) {
    EXPECT_EQ(cpu(features).num_tables, ChooseTableShape(features).num_tables) << features;
    EXPECT_EQ(cpu(features).bits_per_table, ChooseTableShape(features).bits_per_table) << features;
  }
  const TableShape screening = cpu(16384, TableShapeGoal::kScreening);
  EXPECT_EQ(screening.num_tables, ChooseTableShape(16384, 0, 0, TableShapeGoal::kScreening).num_tables);
  EXPECT_EQ(ChooseTableShape(16384, 8, 0, TableShapeGoal::kRecall, TableShapeBackend::kCpu).num_tables, 8);
  EXPECT_EQ(ChooseTableShape(16384, 8, 0, TableShapeGoal::kRecall, TableShapeBackend::kCpu).bits_per_table, 8);
  EXPECT_EQ(ChooseTableShape(16384, 0, 8, TableShapeGoal::kRecall, TableShapeBackend::kCpu).bits_per_table, 8);
  EXPECT_EQ(ChooseTableShape(16384).num_tables, 8);  // the GPU's shape is unchanged
  EXPECT_EQ(ChooseTableShape(16384).bits_per_table, 8);
}

TEST(TableShape, EveryShapeFitsTheGpuLimits) {
  for (size_t features = 1; features <= (size_t{1} << 24); features = features * 3 / 2 + 1) {
    const TableShape shape = ChooseTableShape(features);
    EXPECT_GE(shape.num_tables, 1);
    EXPECT_LE(shape.num_tables, kMaxShapeTables);
    EXPECT_GE(shape.bits_per_table, 1);
    EXPECT_LE(shape.num_tables * shape.bits_per_table, kMaxSignatureBits) << features;
  }
  // Past 8 bits no number of tables within 64 bits holds the probability:
  // the bits stop there.
  EXPECT_LT(TableCollisionProbability(64 / 9, 9), TableCollisionProbability(8, 7) - kMaxCollisionLoss);
  EXPECT_GE(TableCollisionProbability(64 / 8, 8), TableCollisionProbability(8, 7) - kMaxCollisionLoss);
}

TEST(TableShape, ExplicitValuesWin) {
  // Both given: kept as they are, whatever the size.
  for (size_t features : {500, 8192, 65536}) {
    const TableShape shape = ChooseTableShape(features, 10, 10);
    EXPECT_EQ(shape.num_tables, 10);
    EXPECT_EQ(shape.bits_per_table, 10);
  }
  // Bits given: the tables that keep the probability for them.
  EXPECT_EQ(ChooseTableShape(65536, 0, 7).num_tables, 8);
  EXPECT_EQ(ChooseTableShape(65536, 0, 6).num_tables, 7);
  EXPECT_EQ(ChooseTableShape(65536, 0, 7).bits_per_table, 7);
  // Tables given: bits from the size, within 64 bits in all.
  EXPECT_EQ(ChooseTableShape(16384, 8, 0).num_tables, 8);
  EXPECT_EQ(ChooseTableShape(16384, 8, 0).bits_per_table, 8);
  // 6 tables of 8 bits would lose too much (0.90): 6 x 7.
  EXPECT_EQ(ChooseTableShape(16384, 6, 0).num_tables, 6);
  EXPECT_EQ(ChooseTableShape(16384, 6, 0).bits_per_table, 7);
  EXPECT_EQ(ChooseTableShape(4096, 6, 0).bits_per_table, 7);
  EXPECT_EQ(ChooseTableShape(1 << 20, 12, 0).bits_per_table, 5);

  CasHashOptions options;
  options.num_tables = 9;
  options.bits_per_table = 11;
  const CasHashOptions resolved = ResolveTableShape(options, 2048);
  EXPECT_EQ(resolved.num_tables, 9);
  EXPECT_EQ(resolved.bits_per_table, 11);
  const CasHashOptions chosen = ResolveTableShape(CasHashOptions(), 16384);
  EXPECT_EQ(chosen.num_tables, 8);
  EXPECT_EQ(chosen.bits_per_table, 8);
  EXPECT_EQ(chosen.tau, CasHashOptions().tau);
}

TEST(TableShape, AScreeningCascadeTakesSmallerBuckets) {
  const auto screening = [](size_t features, int tables = 0, int bits = 0) {
    return ChooseTableShape(features, tables, bits, TableShapeGoal::kScreening);
  };
  // Below 4,096 features: one bit more than recall while the collision
  // floor holds, 8 x 8 where recall takes 8 x 7.
  for (size_t features : {size_t{100}, size_t{2048}, size_t{4095}}) {
    EXPECT_EQ(screening(features).num_tables, 8) << features;
    EXPECT_EQ(screening(features).bits_per_table, 8) << features;
  }
  // From 4,096 on: 3 tables, buckets of 16-31 features, at most 3 x 10
  // (kBucketScreeningMaxBits, the widest measured).
  const std::vector<std::pair<size_t, int>> bits_by_size = {
      {0, 9}, {4096, 8}, {7028, 8}, {8191, 8}, {8192, 9}, {12500, 9}, {16384, 10}, {32768, 10}, {size_t{1} << 20, 10}};
  for (const auto& [features, bits] : bits_by_size) {
    EXPECT_EQ(screening(features).num_tables, 3) << features;
    EXPECT_EQ(screening(features).bits_per_table, bits) << features;
    EXPECT_TRUE(IsBucketScreeningShape(features, 0, 0, TableShapeGoal::kScreening)) << features;
  }
  // About 48 candidates per query at 8,192 and 16,384 features, against
  // 8 x 8's 256 and 7 x 9's 224.
  EXPECT_EQ(3 * 8192 / (1 << 9), 48);
  EXPECT_EQ(3 * 16384 / (1 << 10), 48);
  // The rematch threshold of this shape applies to it alone: not below
  // 4,096 features, not for recall, not where tables or bits were set.
  EXPECT_FALSE(IsBucketScreeningShape(4095, 0, 0, TableShapeGoal::kScreening));
  EXPECT_FALSE(IsBucketScreeningShape(8192, 0, 0, TableShapeGoal::kRecall));
  EXPECT_FALSE(IsBucketScreeningShape(8192, 3, 0, TableShapeGoal::kScreening));
  EXPECT_FALSE(IsBucketScreeningShape(8192, 0, 9, TableShapeGoal::kScreening));
  // 12 matches at six tables scale to about 8.7 at three; 8 was measured.
  EXPECT_NEAR(12 * TableCollisionProbability(3, 9) / TableCollisionProbability(6, 9), 8.7, 0.1);
  EXPECT_LE(kBucketScreeningRematchMinMatches, 9);
  // Explicit bits are kept; explicit tables get the extra bit only within
  // 64 signature bits and the floor, whatever the size.
  EXPECT_EQ(screening(8192, 0, 7).bits_per_table, 7);
  EXPECT_EQ(screening(8192, 0, 7).num_tables, 8);
  EXPECT_EQ(screening(8192, 8, 0).bits_per_table, 8);
  EXPECT_EQ(screening(8192, 16, 0).bits_per_table, 4);  // 16 x 5 > 64 bits
  EXPECT_EQ(screening(8192, 4, 0).bits_per_table, 7);   // 4 x 8: 0.69
  EXPECT_EQ(screening(16384, 7, 0).bits_per_table, 8);  // recall 7 x 7, one bit more
  const CasHashOptions resolved = ResolveTableShape(CasHashOptions(), 8192, TableShapeGoal::kScreening);
  EXPECT_EQ(resolved.num_tables, 3);
  EXPECT_EQ(resolved.bits_per_table, 9);
  EXPECT_EQ(DescribeTableShape(CasHashOptions(), resolved, 8192, 300, TableShapeGoal::kScreening),
            "Hash tables: 3 x 9 bits (chosen for 8192 features per image, the median of 300 images, buckets of "
            "about 16 features: the exact rematch decides)");
  const CasHashOptions small = ResolveTableShape(CasHashOptions(), 2048, TableShapeGoal::kScreening);
  EXPECT_EQ(DescribeTableShape(CasHashOptions(), small, 2048, 300, TableShapeGoal::kScreening),
            "Hash tables: 8 x 8 bits (chosen for 2048 features per image, the median of 300 images, a bit more "
            "than for recall: the exact rematch decides)");
}

TEST(TableShape, RunSizeIsTheMedianAfterMaxNumMatches) {
  EXPECT_EQ(TypicalFeatureCount({}, 32768), 0u);
  EXPECT_EQ(TypicalFeatureCount({100, 9000, 20000}, 32768), 9000u);
  // The upper middle value of an even count; rows beyond max_num_matches
  // are not matched, so they do not count.
  EXPECT_EQ(TypicalFeatureCount({100, 40000, 40000, 200}, 32768), 32768u);
  EXPECT_EQ(TypicalFeatureCount({20000, 20000, 20000}, 8192), 8192u);
}

TEST(TableShape, DescriptionSaysWhereTheShapeComesFrom) {
  CasHashOptions requested;
  const CasHashOptions resolved = ResolveTableShape(requested, 16384);
  EXPECT_EQ(DescribeTableShape(requested, resolved, 16384, 300),
            "Hash tables: 8 x 8 bits (chosen for 16384 features per image, the median of 300 images)");
  requested.num_tables = 10;
  requested.bits_per_table = 10;
  EXPECT_EQ(DescribeTableShape(requested, requested, 16384, 300), "Hash tables: 10 x 10 bits (as set by the options)");
}

TEST(TableShape, MatcherFromOptionsAtZeroEqualsEightBySeven) {
  // A matcher created without a run's feature counts uses the reference
  // shape: the same matches as 8 x 7 given explicitly.
  std::mt19937 rng(3);
  FeatureDescriptors a, b;
  for (int k = 0; k < 400; ++k) {
    const auto row = testing_support::RandomSift(&rng);
    a.data.insert(a.data.end(), row.begin(), row.end());
    std::vector<uint8_t> noisy = row;
    noisy[k % 128] = static_cast<uint8_t>(noisy[k % 128] ^ 3);
    b.data.insert(b.data.end(), noisy.begin(), noisy.end());
  }
  const MeanDescriptor mean = ComputeMeanDescriptor({&a, &b});
  const CasHashOptions automatic = testing_support::CascadeOptions();
  CasHashOptions explicit_shape = automatic;
  explicit_shape.num_tables = 8;
  explicit_shape.bits_per_table = 7;
  auto run = [&](const CasHashOptions& options) {
    auto matcher = CreateCpuFeatureMatcher(SiftMatchingOptions(), options, mean);
    matcher->AddImage(1, a);
    matcher->AddImage(2, b);
    return matcher->Match({{1, 2}}).front();
  };
  const FeatureMatches expected = run(explicit_shape);
  EXPECT_GT(expected.size(), 300u);
  EXPECT_EQ(run(automatic), expected);
}

}  // namespace
}  // namespace cashash
