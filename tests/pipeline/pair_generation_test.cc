#include "cashash/pipeline/pair_generation.h"

#include <set>

#include <gtest/gtest.h>

#include "cashash/base/pair_id.h"

namespace cashash {
namespace {

std::vector<image_t> Ids(size_t n) {
  std::vector<image_t> ids;
  for (size_t i = 0; i < n; ++i) ids.push_back(static_cast<image_t>(3 * i + 1));  // not contiguous
  return ids;
}

// Every unordered pair exactly once, each chunk's images cover its pairs.
void ExpectExhaustive(size_t n, int block_size) {
  const std::vector<PairChunk> chunks = ExhaustivePairChunks(Ids(n), block_size);
  std::set<pair_t> seen;
  for (const PairChunk& chunk : chunks) {
    EXPECT_FALSE(chunk.pairs.empty());
    EXPECT_LE(chunk.images.size(), static_cast<size_t>(2 * block_size));
    const std::set<image_t> images(chunk.images.begin(), chunk.images.end());
    for (const ImagePair& pair : chunk.pairs) {
      EXPECT_NE(pair.first, pair.second);
      EXPECT_TRUE(images.count(pair.first) && images.count(pair.second));
      EXPECT_TRUE(seen.insert(ImagePairToPairId(pair.first, pair.second)).second) << "pair visited twice";
    }
  }
  EXPECT_EQ(seen.size(), n * (n - 1) / 2) << "n=" << n << " block_size=" << block_size;
}

TEST(PairGeneration, ExhaustiveVisitsEveryPairOnceForOddSizes) {
  for (size_t n : {0, 1, 2, 3, 7, 50, 51, 101}) {
    for (int block_size : {2, 3, 10, 50, 200}) ExpectExhaustive(n, block_size);
  }
}

TEST(PairGeneration, ExhaustiveBlocksAreNumbered) {
  const std::vector<PairChunk> chunks = ExhaustivePairChunks(Ids(5), 2);
  // Blocks {0,1}, {2,3}, {4}: block pairs (0,0) (0,1) (0,2) (1,1) (1,2); (2,2) has no pair.
  ASSERT_EQ(chunks.size(), 5u);
  EXPECT_EQ(chunks[0].num_blocks, 3);
  EXPECT_EQ(chunks.back().block_i, 1);
  EXPECT_EQ(chunks.back().block_j, 2);
}

TEST(PairGeneration, ListChunksRespectLimits) {
  std::vector<ImagePair> pairs;
  for (image_t i = 1; i <= 20; ++i)
    for (image_t j = i + 1; j <= 20; ++j) pairs.emplace_back(i, j);
  const std::vector<PairChunk> chunks = ListPairChunks(pairs, 30, 8);
  size_t total = 0;
  for (const PairChunk& chunk : chunks) {
    EXPECT_LE(chunk.pairs.size(), 30u);
    EXPECT_LE(chunk.images.size(), 8u);
    total += chunk.pairs.size();
  }
  EXPECT_EQ(total, pairs.size());
}

TEST(PairGeneration, RemovePairsDropsEmptyChunksAndUnusedImages) {
  std::vector<PairChunk> chunks = ExhaustivePairChunks(Ids(4), 2);
  // Remove every pair touching image 1 (the first id).
  chunks = RemovePairs(std::move(chunks), [](const ImagePair& p) { return p.first == 1 || p.second == 1; });
  size_t total = 0;
  for (const PairChunk& chunk : chunks) {
    total += chunk.pairs.size();
    for (image_t id : chunk.images) EXPECT_NE(id, 1u);
  }
  EXPECT_EQ(total, 3u);  // pairs among the 3 other images
}

TEST(PairId, MatchesColmapFormulaAndRoundTrips) {
  EXPECT_EQ(ImagePairToPairId(1, 2), 2147483647ull * 1 + 2);
  EXPECT_EQ(ImagePairToPairId(2, 1), ImagePairToPairId(1, 2));
  const ImagePair pair = PairIdToImagePair(ImagePairToPairId(70000, 12));
  EXPECT_EQ(pair.first, 12u);
  EXPECT_EQ(pair.second, 70000u);
  EXPECT_TRUE(SwapImagePair(5, 3));
  EXPECT_FALSE(SwapImagePair(3, 5));
}

}  // namespace
}  // namespace cashash
