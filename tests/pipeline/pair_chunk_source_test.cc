// ScheduledChunkSource makes, one at a time, exactly the chunks that
// ScheduledPairChunks lists (thinned by RemovePairs on resume): same order,
// pairs, images, block and group numbers, for many sizes, with and without
// completed pairs left out. PairTriangle, the resume bits it reads.
#include "cashash/pipeline/pair_chunk_source.h"

#include <algorithm>
#include <map>
#include <random>
#include <stdexcept>
#include <set>
#include <string>

#include <gtest/gtest.h>

#include "cashash/base/pair_id.h"
#include "cashash/pipeline/feature_cache.h"

namespace cashash {
namespace {

std::vector<image_t> Ids(size_t n) {
  std::vector<image_t> ids;
  for (size_t i = 0; i < n; ++i) ids.push_back(static_cast<image_t>(5 * i + 2));
  // Not contiguous, and not sorted: positions and ids differ.
  std::shuffle(ids.begin(), ids.end(), std::mt19937(static_cast<unsigned>(n)));
  return ids;
}

void ExpectSameChunk(const PairChunk& made, const PairChunk& listed) {
  EXPECT_EQ(made.pairs, listed.pairs);
  EXPECT_EQ(made.images, listed.images);
  EXPECT_EQ(made.block_i, listed.block_i);
  EXPECT_EQ(made.block_j, listed.block_j);
  EXPECT_EQ(made.num_blocks, listed.num_blocks);
  EXPECT_EQ(made.group_i, listed.group_i);
  EXPECT_EQ(made.group_j, listed.group_j);
  EXPECT_EQ(made.num_groups, listed.num_groups);
}

// The source's chunks against the reference list, one by one, and its
// counts and outlines.
void ExpectSameChunks(const PairChunkSource& source, const std::vector<PairChunk>& reference) {
  ASSERT_EQ(source.size(), reference.size());
  size_t num_pairs = 0;
  for (size_t k = 0; k < reference.size(); ++k) {
    SCOPED_TRACE("chunk " + std::to_string(k));
    const PairChunk made = source.Chunk(k);
    ExpectSameChunk(made, reference[k]);
    EXPECT_EQ(source.NumPairs(k), reference[k].pairs.size());
    PairChunk outline = reference[k];
    outline.pairs.clear();
    ExpectSameChunk(source.Outline(k), outline);
    num_pairs += reference[k].pairs.size();
  }
  EXPECT_EQ(source.num_pairs(), num_pairs);
}

struct Case {
  size_t n;
  int block_size;
  int blocks_per_group;
};

std::vector<Case> Cases() {
  std::vector<Case> cases;
  for (size_t n : {0, 1, 2, 3, 5, 11, 50, 51, 101}) {
    for (int block_size : {1, 2, 3, 10, 50, 200}) {
      for (int blocks_per_group : {1, 2, 3, 100}) cases.push_back({n, block_size, blocks_per_group});
    }
  }
  return cases;
}

std::string Describe(const Case& c) {
  return "n=" + std::to_string(c.n) + " block_size=" + std::to_string(c.block_size) +
         " blocks_per_group=" + std::to_string(c.blocks_per_group);
}

TEST(ScheduledChunkSource, SameChunksAsScheduledPairChunks) {
  for (const Case& c : Cases()) {
    SCOPED_TRACE(Describe(c));
    const std::vector<image_t> ids = Ids(c.n);
    const ScheduledChunkSource source(ids, c.block_size, c.blocks_per_group);
    ExpectSameChunks(source, ScheduledPairChunks(ids, c.block_size, c.blocks_per_group));
  }
}

// Resume holes: a random share of the pairs done, every pair of some
// chunks done (they disappear), every pair done (nothing left).
TEST(ScheduledChunkSource, SameChunksAsRemovePairsOnResume) {
  std::mt19937 rng(11);
  for (const Case& c : Cases()) {
    const std::vector<image_t> ids = Ids(c.n);
    const std::vector<PairChunk> all = ScheduledPairChunks(ids, c.block_size, c.blocks_per_group);
    std::map<image_t, size_t> position;
    for (size_t p = 0; p < ids.size(); ++p) position[ids[p]] = p;
    for (int done_in : {2, 7, 1}) {  // about half, about a seventh, every pair
      SCOPED_TRACE(Describe(c) + " done 1 in " + std::to_string(done_in));
      PairTriangle done(ids.size());
      std::set<pair_t> done_pairs;
      for (size_t k = 0; k < all.size(); ++k) {
        const bool whole_chunk = k % 3 == 1;
        for (const ImagePair& pair : all[k].pairs) {
          if (!whole_chunk && rng() % done_in != 0) continue;
          done.Set(position.at(pair.first), position.at(pair.second));
          done_pairs.insert(ImagePairToPairId(pair.first, pair.second));
        }
      }
      const std::vector<PairChunk> left = RemovePairs(all, [&](const ImagePair& pair) {
        return done_pairs.count(ImagePairToPairId(pair.first, pair.second)) > 0;
      });
      const ScheduledChunkSource source(ids, c.block_size, c.blocks_per_group, done);
      ExpectSameChunks(source, left);
      if (done_in == 1) {
        EXPECT_EQ(source.size(), 0u);
      }
      // The cache plans the same steps from the outlines.
      EXPECT_EQ(GroupFeatureCache::Steps(source), GroupFeatureCache::Steps(left));
    }
  }
}

TEST(ScheduledChunkSource, CountsPairsWithoutMakingThem) {
  // 20,000 images in blocks of 50: 80,200 block pairs, 200 million pairs.
  std::vector<image_t> ids;
  for (image_t i = 1; i <= 20000; ++i) ids.push_back(i);
  const ScheduledChunkSource source(ids, 50, 400);
  EXPECT_EQ(source.size(), 400u * 401u / 2u);
  EXPECT_EQ(source.num_pairs(), 20000u * 19999u / 2u);
  EXPECT_EQ(source.Chunk(source.size() - 1).pairs.size(), source.NumPairs(source.size() - 1));
}

TEST(ScheduledChunkSource, RefusesCompletedPairsOfAnotherRun) {
  PairTriangle done(5);
  done.Set(0, 1);
  EXPECT_THROW(ScheduledChunkSource(Ids(6), 2, 1, done), std::invalid_argument);
}

TEST(ChunkList, ServesTheListItViews) {
  std::vector<ImagePair> pairs;
  for (image_t i = 1; i < 30; ++i) pairs.emplace_back(i, i + 1);
  const std::vector<PairChunk> chunks = ListPairChunks(pairs, 4, 6);
  const ChunkList list(&chunks);
  ExpectSameChunks(list, chunks);
  EXPECT_EQ(AllChunks(list).size(), chunks.size());
}

TEST(PairTriangle, SetTestAndCountInRow) {
  const size_t n = 37;
  PairTriangle bits(n);
  EXPECT_EQ(bits.memory_bytes(), 0u);  // nothing held until a pair is set
  EXPECT_FALSE(bits.Test(3, 4));
  EXPECT_EQ(bits.CountInRow(3, 4, n), 0u);
  std::mt19937 rng(5);
  std::set<std::pair<size_t, size_t>> set;
  for (int k = 0; k < 300; ++k) {
    const size_t i = rng() % n, j = rng() % n;
    if (i == j) continue;
    const bool fresh = set.insert({std::min(i, j), std::max(i, j)}).second;
    EXPECT_EQ(bits.Set(i, j), fresh);
  }
  EXPECT_EQ(bits.count(), set.size());
  EXPECT_LE(bits.memory_bytes(), (n * (n - 1) / 2 + 63) / 64 * 8);
  for (size_t a = 0; a < n; ++a) {
    for (size_t b = a + 1; b < n; ++b) {
      EXPECT_EQ(bits.Test(a, b), set.count({a, b}) > 0);
      EXPECT_EQ(bits.Test(b, a), set.count({a, b}) > 0);
    }
    for (size_t begin = a + 1; begin <= n; begin += 3) {
      for (size_t end = begin; end <= n; end += 5) {
        size_t expected = 0;
        for (size_t b = begin; b < end; ++b) expected += set.count({a, b});
        EXPECT_EQ(bits.CountInRow(a, begin, end), expected) << a << " " << begin << " " << end;
      }
    }
  }
}

}  // namespace
}  // namespace cashash
