// Cascade Hashing projections and hash codes (cascade_hashing.h, steps 1-3).
#include "cashash/matching/cascade_hashing.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "cashash/matchers/feature_matcher.h"

namespace cashash {
namespace {

FeatureDescriptors RandomDescriptors(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> value(0, 255);
  FeatureDescriptors descriptors;
  descriptors.data.resize(n * kDescriptorDim);
  for (uint8_t& v : descriptors.data) v = static_cast<uint8_t>(value(rng));
  return descriptors;
}

CasHashOptions Options(int tables, int bits, uint64_t seed) {
  CasHashOptions options;
  options.num_tables = tables;
  options.bits_per_table = bits;
  options.random_seed = seed;
  return options;
}

TEST(CascadeProjections, DeterministicPerSeedAndDifferentAcrossSeeds) {
  const CascadeProjections a = GenerateCascadeProjections(Options(6, 8, 7));
  const CascadeProjections b = GenerateCascadeProjections(Options(6, 8, 7));
  const CascadeProjections c = GenerateCascadeProjections(Options(6, 8, 8));
  ASSERT_EQ(a.matrix.size(), size_t(6 * 8 + 128) * kDescriptorDim);
  EXPECT_EQ(a.num_rows(), 6 * 8 + 128);
  EXPECT_EQ(a.matrix, b.matrix);
  size_t differing = 0;
  for (size_t i = 0; i < a.matrix.size(); ++i) differing += a.matrix[i] != c.matrix[i];
  EXPECT_GT(differing, a.matrix.size() * 9 / 10);
}

TEST(CascadeProjections, MoreTablesExtendTheSameStream) {
  // The stream is drawn row-major, so the first rows of a larger bucket
  // matrix equal a smaller one's: an easy check of the documented order.
  const CascadeProjections small = GenerateCascadeProjections(Options(1, 8, 3));
  const CascadeProjections large = GenerateCascadeProjections(Options(2, 8, 3));
  for (size_t i = 0; i < size_t(8) * kDescriptorDim; ++i) ASSERT_EQ(small.matrix[i], large.matrix[i]);
}

TEST(CascadeProjections, IntegerEntriesWithNormalSpread) {
  const CascadeProjections p = GenerateCascadeProjections(Options(8, 10, 1));
  double sum = 0, sum2 = 0;
  for (float v : p.matrix) {
    ASSERT_EQ(v, std::round(v));
    ASSERT_GE(v, -255.f);
    ASSERT_LE(v, 255.f);
    sum += v;
    sum2 += double(v) * v;
  }
  const double n = p.matrix.size();
  const double mean = sum / n;
  const double stddev = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(mean, 0.0, 1.0);
  EXPECT_NEAR(stddev, 64.0, 1.5);
}

TEST(CascadeProjections, FixedValuesPinTheSampler) {
  // A change here changes every backend's matches for a given seed.
  const CascadeProjections zero = GenerateCascadeProjections(Options(1, 1, 0));
  const std::vector<float> expected_zero = {3, 89, 9, -108, 38, 16, 43, -71};
  EXPECT_EQ(std::vector<float>(zero.matrix.begin(), zero.matrix.begin() + 8), expected_zero);
  const CascadeProjections other = GenerateCascadeProjections(Options(1, 1, 12345));
  const std::vector<float> expected_other = {-132, 22, -90, 15, -154, -155, -11, 6};
  EXPECT_EQ(std::vector<float>(other.matrix.begin(), other.matrix.begin() + 8), expected_other);
}

// Reference for one bit: sign of the projection of (descriptor - round(mean)),
// computed in double (exact for these integer values).
bool ReferenceBit(const CascadeProjections& p, int row, const uint8_t* desc, const MeanDescriptor& mean) {
  double dot = 0;
  for (int d = 0; d < kDescriptorDim; ++d) {
    dot += double(p.matrix[size_t(row) * kDescriptorDim + d]) * (double(desc[d]) - std::round(mean[d]));
  }
  return dot > 0;
}

void ExpectBitsMatchReference(const CascadeProjections& p, const FeatureDescriptors& descriptors,
                              size_t rows, const MeanDescriptor& mean) {
  const HashedFeatures hashed = HashDescriptors(descriptors, rows, p, mean);
  ASSERT_EQ(hashed.num_features, rows);
  ASSERT_EQ(hashed.num_tables, p.num_tables);
  ASSERT_EQ(hashed.remap_codes.size(), 2 * rows);
  ASSERT_EQ(hashed.bucket_ids.size(), rows * p.num_tables);
  for (size_t i = 0; i < rows; ++i) {
    const uint8_t* desc = descriptors.row(i);
    for (int t = 0; t < p.num_tables; ++t) {
      for (int b = 0; b < p.bits_per_table; ++b) {
        const bool bit = (hashed.bucket_ids[i * p.num_tables + t] >> b) & 1u;
        ASSERT_EQ(bit, ReferenceBit(p, t * p.bits_per_table + b, desc, mean))
            << "feature " << i << " table " << t << " bit " << b;
      }
      ASSERT_LT(hashed.bucket_ids[i * p.num_tables + t], 1u << p.bits_per_table);
    }
    for (int b = 0; b < CasHashOptions::kRemapBits; ++b) {
      const bool bit = (hashed.remap_codes[2 * i + b / 64] >> (b % 64)) & 1u;
      ASSERT_EQ(bit, ReferenceBit(p, p.num_bucket_rows() + b, desc, mean)) << "remap bit " << b;
    }
  }
}

TEST(HashDescriptors, BitsAreTheSignOfTheProjection) {
  const CascadeProjections p = GenerateCascadeProjections(Options(6, 8, 11));
  const FeatureDescriptors descriptors = RandomDescriptors(300, 5);
  MeanDescriptor mean;
  for (int d = 0; d < kDescriptorDim; ++d) mean[d] = 100.3f + d * 0.25f;  // fractional: rounded
  ExpectBitsMatchReference(p, descriptors, 300, mean);
}

TEST(HashDescriptors, HashesOnlyTheFirstRowsAndMixedSplits) {
  const CascadeProjections p = GenerateCascadeProjections(Options(3, 13, 2));
  const FeatureDescriptors descriptors = RandomDescriptors(50, 6);
  const MeanDescriptor mean = ComputeMeanDescriptor({&descriptors});
  ExpectBitsMatchReference(p, descriptors, 20, mean);
  EXPECT_THROW(HashDescriptors(descriptors, 51, p, mean), std::invalid_argument);
  EXPECT_EQ(HashDescriptors(descriptors, 0, p, mean).num_features, 0u);
}

TEST(HashDescriptors, NonIntegerProjectionsFollowTheSameRule) {
  CascadeProjections p = GenerateCascadeProjections(Options(2, 4, 9));
  for (float& v : p.matrix) v *= 0.37f;  // no longer integers: the general path
  const FeatureDescriptors descriptors = RandomDescriptors(100, 8);
  MeanDescriptor mean;
  mean.fill(127.f);
  ExpectBitsMatchReference(p, descriptors, 100, mean);
}

TEST(HashDescriptors, ZeroProjectionGivesBitZero) {
  // A feature equal to the mean projects to exactly 0 everywhere: all bits 0.
  const CascadeProjections p = GenerateCascadeProjections(Options(2, 8, 1));
  FeatureDescriptors descriptors;
  descriptors.data.assign(kDescriptorDim, 42);
  MeanDescriptor mean;
  mean.fill(42.f);
  const HashedFeatures hashed = HashDescriptors(descriptors, 1, p, mean);
  EXPECT_EQ(hashed.bucket_ids[0], 0u);
  EXPECT_EQ(hashed.bucket_ids[1], 0u);
  EXPECT_EQ(hashed.remap_codes[0], 0u);
  EXPECT_EQ(hashed.remap_codes[1], 0u);
}

TEST(ComputeMeanDescriptor, RoundedMeanOverAllSets) {
  FeatureDescriptors a, b, empty;
  a.data.assign(2 * kDescriptorDim, 10);
  b.data.assign(kDescriptorDim, 0);
  b.data[0] = 200;  // dim 0: (10 + 10 + 200) / 3 = 73.3 -> 73
  b.data[1] = 12;   // dim 1: (10 + 10 + 12) / 3 = 10.67 -> 11
  const MeanDescriptor mean = ComputeMeanDescriptor({&a, &b, &empty});
  EXPECT_EQ(mean[0], 73.f);
  EXPECT_EQ(mean[1], 11.f);
  EXPECT_EQ(mean[2], 7.f);  // 20 / 3 = 6.67
  const MeanDescriptor none = ComputeMeanDescriptor({&empty});
  for (float v : none) EXPECT_EQ(v, 0.f);
}

}  // namespace
}  // namespace cashash
