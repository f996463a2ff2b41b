// Bucket tables and Cascade Hashing matching (cascade_hashing.h, steps 4-6).
#include "cashash/matching/cascade_matcher.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "cashash/matching/brute_force_matcher.h"
#include "cashash/matching/descriptor_distance.h"
#include "cashash/matchers/feature_matcher.h"
#include "synthetic_sift.h"
#include "cascade_options.h"

namespace cashash {
namespace {

using testing_support::CascadeOptions;
using testing_support::RandomSift;

// a: n random features; b: perturbed copies of a's first n_copies features
// (shuffled; every fifth copied twice) plus unrelated ones; every seventh
// feature of a has a near twin in a, so one-way and mutual matches differ.
void MakePair(size_t n, size_t n_copies, int amplitude, uint32_t seed, FeatureDescriptors* a,
              FeatureDescriptors* b) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> noise(-amplitude, amplitude);
  std::vector<std::vector<uint8_t>> rows_a, rows_b;
  for (size_t i = 0; i < n; ++i) rows_a.push_back(RandomSift(&rng));
  for (size_t i = 0; i < n; ++i) {
    if (i < n_copies) {
      std::vector<uint8_t> copy = rows_a[i];
      for (uint8_t& x : copy) x = static_cast<uint8_t>(std::clamp(int(x) + noise(rng), 0, 255));
      rows_b.push_back(copy);
      if (i % 5 == 0) {
        for (uint8_t& x : copy) x = static_cast<uint8_t>(std::clamp(int(x) + noise(rng), 0, 255));
        rows_b.push_back(copy);
      }
    } else {
      rows_b.push_back(RandomSift(&rng));
    }
  }
  rows_b.resize(n);
  for (size_t i = 0; i < n; i += 7) {
    std::vector<uint8_t> twin = rows_a[i];
    for (uint8_t& x : twin) x = static_cast<uint8_t>(std::clamp(int(x) + noise(rng), 0, 255));
    rows_a[n - 1 - i] = twin;
  }
  std::shuffle(rows_b.begin(), rows_b.end(), rng);
  a->data.clear();
  b->data.clear();
  for (const auto& r : rows_a) a->data.insert(a->data.end(), r.begin(), r.end());
  for (const auto& r : rows_b) b->data.insert(b->data.end(), r.begin(), r.end());
}

struct Hashed {
  CascadeImage a, b;
};

Hashed HashPair(const FeatureDescriptors& a, const FeatureDescriptors& b, const CasHashOptions& o) {
  const CascadeProjections p = GenerateCascadeProjections(o);
  const MeanDescriptor mean = ComputeMeanDescriptor({&a, &b});
  return {BuildCascadeImage(a, a.rows(), p, mean), BuildCascadeImage(b, b.rows(), p, mean)};
}

void ExpectValidCsr(const HashedFeatures& hashed, const BucketTables& tables) {
  const size_t n = hashed.num_features;
  ASSERT_EQ(tables.features.size(), n * tables.num_tables);
  for (int t = 0; t < tables.num_tables; ++t) {
    std::vector<int> times_seen(n, 0);
    for (uint32_t bucket = 0; bucket < tables.num_buckets(); ++bucket) {
      const size_t begin = tables.begin(t, bucket), end = tables.end(t, bucket);
      ASSERT_LE(begin, end);
      for (size_t p = begin; p < end; ++p) {
        const uint32_t f = tables.features[p];
        ASSERT_LT(f, n);
        ++times_seen[f];
        EXPECT_EQ(hashed.bucket_ids[f * tables.num_tables + t], bucket);
        EXPECT_EQ(tables.codes[2 * p], hashed.remap_codes[2 * f]);
        EXPECT_EQ(tables.codes[2 * p + 1], hashed.remap_codes[2 * f + 1]);
        if (p > begin) {
          EXPECT_LT(tables.features[p - 1], f);  // ascending in a bucket
        }
      }
    }
    for (size_t f = 0; f < n; ++f) ASSERT_EQ(times_seen[f], 1) << "table " << t << " feature " << f;
  }
}

TEST(BucketTables, EveryFeatureExactlyOncePerTable) {
  FeatureDescriptors a, b;
  MakePair(700, 300, 10, 1, &a, &b);
  CasHashOptions o = CascadeOptions();
  o.num_tables = 5;
  o.bits_per_table = 6;
  const Hashed h = HashPair(a, b, o);
  ExpectValidCsr(h.a.hashed, h.a.buckets);
  ExpectValidCsr(h.b.hashed, h.b.buckets);
}

TEST(BucketTables, SkewedBucketsHoldEverything) {
  // 900 identical descriptors fall into one bucket of every table: no
  // capacity limit may drop any of them.
  std::mt19937 rng(2);
  const std::vector<uint8_t> same = RandomSift(&rng);
  FeatureDescriptors d;
  for (int i = 0; i < 1000; ++i) {
    const std::vector<uint8_t> row = i % 10 == 0 ? RandomSift(&rng) : same;
    d.data.insert(d.data.end(), row.begin(), row.end());
  }
  CasHashOptions o = CascadeOptions();
  o.num_tables = 4;
  o.bits_per_table = 10;
  const CascadeProjections p = GenerateCascadeProjections(o);
  const MeanDescriptor mean = ComputeMeanDescriptor({&d});
  const CascadeImage image = BuildCascadeImage(d, d.rows(), p, mean);
  ExpectValidCsr(image.hashed, image.buckets);
  const uint32_t bucket = image.hashed.bucket_ids[1 * o.num_tables + 0];
  EXPECT_GE(image.buckets.end(0, bucket) - image.buckets.begin(0, bucket), 900u);
}

TEST(BucketTables, EmptyImage) {
  HashedFeatures hashed;
  hashed.num_tables = 3;
  const BucketTables tables = BuildBucketTables(hashed, 4);
  EXPECT_TRUE(tables.features.empty());
  for (uint32_t bucket = 0; bucket < 16; ++bucket) EXPECT_EQ(tables.begin(2, bucket), tables.end(2, bucket));
}

// Direct transcription of the definition's steps 4 and 5 for one query.
int ReferenceQuery(const CascadeImage& q_image, size_t q, const CascadeImage& t_image,
                   const SiftMatchingOptions& s, const CasHashOptions& o) {
  const int tables = q_image.hashed.num_tables;
  std::vector<std::pair<int, uint32_t>> candidates, beyond;  // (hamming, index)
  for (size_t f = 0; f < t_image.num_features(); ++f) {
    bool shares = false;
    for (int t = 0; t < tables; ++t) {
      shares |= q_image.hashed.bucket_ids[q * tables + t] == t_image.hashed.bucket_ids[f * tables + t];
    }
    if (!shares) continue;
    const int hamming =
        __builtin_popcountll(q_image.hashed.remap_codes[2 * q] ^ t_image.hashed.remap_codes[2 * f]) +
        __builtin_popcountll(q_image.hashed.remap_codes[2 * q + 1] ^ t_image.hashed.remap_codes[2 * f + 1]);
    (hamming <= o.tau ? candidates : beyond).push_back({hamming, uint32_t(f)});
  }
  std::sort(candidates.begin(), candidates.end());
  if (candidates.size() > size_t(o.top_k)) candidates.resize(o.top_k);
  std::vector<std::pair<int, uint32_t>> by_dot;  // (-dot, index): best first
  auto add = [&](uint32_t f) {
    int dot = 0;
    for (int d = 0; d < kDescriptorDim; ++d) {
      dot += int(q_image.descriptors.row(q)[d]) * int(t_image.descriptors.row(f)[d]);
    }
    by_dot.push_back({-dot, f});
    std::sort(by_dot.begin(), by_dot.end());
  };
  auto accepted = [&]() {
    if (by_dot.empty() || by_dot[0].first == 0) return false;
    const int second = by_dot.size() > 1 ? -by_dot[1].first : 0;
    return AcceptSiftMatch(-by_dot[0].first, second, float(s.max_ratio), float(s.max_distance));
  };
  for (const auto& c : candidates) add(c.second);
  if (!accepted()) return -1;
  // Step 5b: a thin list is decided again with the nearest beyond tau.
  if (candidates.size() < size_t(kThinListSize)) {
    std::sort(beyond.begin(), beyond.end());
    for (size_t i = 0; i < beyond.size() && i < size_t(kBeyondTauCandidates); ++i) add(beyond[i].second);
    if (!accepted()) return -1;
  }
  return int(by_dot[0].second);
}

TEST(CascadeMatch, OneWayFollowsTheDefinition) {
  FeatureDescriptors a, b;
  MakePair(400, 250, 15, 3, &a, &b);
  for (const int top_k : {1, 2, 5, 10}) {
    for (const int tau : {20, 48, 128}) {
      CasHashOptions o = CascadeOptions();
      o.num_tables = 4;
      o.bits_per_table = 5;
      o.top_k = top_k;
      o.tau = tau;
      const Hashed h = HashPair(a, b, o);
      const SiftMatchingOptions s;
      CascadeScratch scratch;
      CascadeStats stats;
      const std::vector<int> result = CascadeMatchOneWay(h.a, h.b, s, o, &scratch, &stats);
      ASSERT_EQ(result.size(), a.rows());
      for (size_t q = 0; q < a.rows(); ++q) {
        ASSERT_EQ(result[q], ReferenceQuery(h.a, q, h.b, s, o)) << "query " << q << " top_k " << top_k;
      }
      EXPECT_EQ(stats.num_queries, a.rows());
      EXPECT_LE(stats.ranked, stats.within_tau);
      EXPECT_LE(stats.within_tau, stats.bucket_entries);
      EXPECT_LE(stats.ranked, a.rows() * size_t(top_k));
    }
  }
}

TEST(CascadeMatch, EveryCandidateRankedEqualsBruteForce) {
  // 1-bit buckets in 64 tables: every feature shares some bucket with every
  // query; tau = 128 and top_k = n keep them all, so the cascade must return
  // exactly the brute-force matches, under every toggle.
  FeatureDescriptors a, b;
  MakePair(300, 200, 20, 4, &a, &b);
  CasHashOptions o = CascadeOptions();
  o.num_tables = 64;
  o.bits_per_table = 1;
  o.tau = 128;
  o.top_k = 300;
  const Hashed h = HashPair(a, b, o);
  for (const bool cross_check : {true, false}) {
    for (const double max_ratio : {0.8, 1.0}) {
      SiftMatchingOptions s;
      s.cross_check = cross_check;
      s.max_ratio = max_ratio;
      CascadeScratch scratch;
      CascadeStats stats;
      const FeatureMatches cascade = CascadeMatchPair(h.a, h.b, s, o, &scratch, &stats);
      const FeatureMatches exact =
          BruteForceMatchPair(WidenDescriptors(a, a.rows()), WidenDescriptors(b, b.rows()), s);
      EXPECT_GT(exact.size(), 100u);
      EXPECT_EQ(cascade, exact) << "cross_check " << cross_check << " max_ratio " << max_ratio;
      EXPECT_EQ(stats.ranked, stats.num_queries * 300);  // nothing was left out
    }
  }
}

TEST(CascadeMatch, RecallOnPlantedNearDuplicates) {
  FeatureDescriptors a, b;
  MakePair(3000, 2000, 12, 5, &a, &b);
  const CasHashOptions o = CascadeOptions();
  const Hashed h = HashPair(a, b, o);
  const SiftMatchingOptions s;
  CascadeScratch scratch;
  const FeatureMatches cascade = CascadeMatchPair(h.a, h.b, s, o, &scratch);
  const FeatureMatches exact =
      BruteForceMatchPair(WidenDescriptors(a, a.rows()), WidenDescriptors(b, b.rows()), s);
  ASSERT_GT(exact.size(), 900u);
  size_t found = 0;
  for (const FeatureMatch& m : exact) found += std::binary_search(cascade.begin(), cascade.end(), m);
  const double recall = double(found) / exact.size();
  std::printf("recall %.4f (%zu of %zu exact matches)\n", recall, found, exact.size());
  EXPECT_GE(recall, 0.95) << found << " of " << exact.size();
  EXPECT_TRUE(std::is_sorted(cascade.begin(), cascade.end()));
}

// tau 0 is chosen for the run (ResolveRun): the cascade's functions refuse
// it rather than keep only the candidates of equal remap codes.
TEST(CascadeMatch, RefusesATauLeftToTheRun) {
  FeatureDescriptors a, b;
  MakePair(200, 100, 10, 7, &a, &b);
  CasHashOptions o = CascadeOptions();
  const Hashed h = HashPair(a, b, o);
  o.tau = kTauChosen;
  CascadeScratch scratch;
  try {
    CascadeMatchPair(h.a, h.b, SiftMatchingOptions(), o, &scratch);
    ADD_FAILURE() << "matched with tau 0";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("--CasHash.tau 0"), std::string::npos) << e.what();
  }
  EXPECT_THROW(CascadeMatchOneWay(h.a, h.b, SiftMatchingOptions(), o, &scratch), std::invalid_argument);
}

TEST(CascadeMatch, CrossCheckKeepsMutualMatchesOnly) {
  FeatureDescriptors a, b;
  MakePair(500, 300, 25, 6, &a, &b);
  const CasHashOptions o = CascadeOptions();
  const Hashed h = HashPair(a, b, o);
  SiftMatchingOptions s;
  s.cross_check = false;
  CascadeScratch scratch;
  const std::vector<int> ab = CascadeMatchOneWay(h.a, h.b, s, o, &scratch);
  const std::vector<int> ba = CascadeMatchOneWay(h.b, h.a, s, o, &scratch);
  FeatureMatches expected_mutual, expected_one_way;
  for (size_t i = 0; i < ab.size(); ++i) {
    if (ab[i] < 0) continue;
    expected_one_way.push_back({point2D_t(i), point2D_t(ab[i])});
    if (ba[ab[i]] == int(i)) expected_mutual.push_back({point2D_t(i), point2D_t(ab[i])});
  }
  EXPECT_EQ(CascadeMatchPair(h.a, h.b, s, o, &scratch), expected_one_way);
  s.cross_check = true;
  EXPECT_EQ(CascadeMatchPair(h.a, h.b, s, o, &scratch), expected_mutual);
  EXPECT_LT(expected_mutual.size(), expected_one_way.size());
}

TEST(CascadeMatch, EmptyAndSingleFeatureImages) {
  std::mt19937 rng(7);
  FeatureDescriptors empty, one, many;
  one.data = RandomSift(&rng);
  for (int i = 0; i < 20; ++i) {
    const auto r = RandomSift(&rng);
    many.data.insert(many.data.end(), r.begin(), r.end());
  }
  many.data.insert(many.data.end(), one.data.begin(), one.data.end());  // copy at row 20
  const CasHashOptions o = CascadeOptions();
  const CascadeProjections p = GenerateCascadeProjections(o);
  const MeanDescriptor mean = ComputeMeanDescriptor({&many});
  const CascadeImage e = BuildCascadeImage(empty, 0, p, mean);
  const CascadeImage x = BuildCascadeImage(one, 1, p, mean);
  const CascadeImage m = BuildCascadeImage(many, many.rows(), p, mean);
  const SiftMatchingOptions s;
  CascadeScratch scratch;
  EXPECT_TRUE(CascadeMatchPair(e, m, s, o, &scratch).empty());
  EXPECT_TRUE(CascadeMatchPair(m, e, s, o, &scratch).empty());
  EXPECT_TRUE(CascadeMatchPair(e, e, s, o, &scratch).empty());
  EXPECT_TRUE(CascadeMatchOneWay(m, e, s, o, &scratch) == std::vector<int>(21, -1));
  EXPECT_EQ(CascadeMatchPair(x, m, s, o, &scratch), (FeatureMatches{{0, 20}}));
  EXPECT_EQ(CascadeMatchPair(m, x, s, o, &scratch), (FeatureMatches{{20, 0}}));
}

}  // namespace
}  // namespace cashash
