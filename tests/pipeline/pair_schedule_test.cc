// The three-level order of ScheduledPairChunks: every pair once, whatever the
// sizes, and the reloads its design promises (one new group per group pair,
// at most one new block per chunk).
#include <algorithm>
#include <set>

#include <gtest/gtest.h>

#include "cashash/pipeline/pair_generation.h"
#include "cashash/base/pair_id.h"

namespace cashash {
namespace {

std::vector<image_t> Ids(size_t n) {
  std::vector<image_t> ids;
  for (size_t i = 0; i < n; ++i) ids.push_back(static_cast<image_t>(5 * i + 2));  // not contiguous
  return ids;
}

std::set<int> BlocksOf(const PairChunk& chunk) { return {chunk.block_i, chunk.block_j}; }
std::set<int> GroupsOf(const PairChunk& chunk) { return {chunk.group_i, chunk.group_j}; }

size_t CountNew(const std::set<int>& now, const std::set<int>& before) {
  size_t fresh = 0;
  for (int x : now) fresh += before.count(x) ? 0 : 1;
  return fresh;
}

struct Case {
  size_t n;
  int block_size;
  int blocks_per_group;
};

std::vector<Case> OddCases() {
  std::vector<Case> cases;
  // N not a multiple of the block or group size, one block, one group, one
  // block per group, one image in the last block.
  for (size_t n : {0, 1, 2, 3, 5, 7, 10, 11, 50, 51, 101}) {
    for (int block_size : {2, 3, 4, 10, 50, 200}) {
      for (int blocks_per_group : {1, 2, 3, 5, 100}) cases.push_back({n, block_size, blocks_per_group});
    }
  }
  return cases;
}

TEST(PairSchedule, EveryPairExactlyOnceForOddSizes) {
  for (const Case& c : OddCases()) {
    SCOPED_TRACE("n=" + std::to_string(c.n) + " block_size=" + std::to_string(c.block_size) +
                 " blocks_per_group=" + std::to_string(c.blocks_per_group));
    const std::vector<image_t> ids = Ids(c.n);
    const std::vector<PairChunk> chunks = ScheduledPairChunks(ids, c.block_size, c.blocks_per_group);
    std::set<pair_t> seen;
    for (const PairChunk& chunk : chunks) {
      ASSERT_FALSE(chunk.pairs.empty());
      EXPECT_LE(chunk.block_i, chunk.block_j);
      EXPECT_LE(chunk.images.size(), static_cast<size_t>(2 * c.block_size));
      const std::set<image_t> images(chunk.images.begin(), chunk.images.end());
      for (const ImagePair& pair : chunk.pairs) {
        ASSERT_TRUE(images.count(pair.first) && images.count(pair.second));
        // Pair order as ExhaustivePairChunks: earlier position first.
        EXPECT_LT(std::find(ids.begin(), ids.end(), pair.first), std::find(ids.begin(), ids.end(), pair.second));
        EXPECT_TRUE(seen.insert(ImagePairToPairId(pair.first, pair.second)).second) << "pair visited twice";
      }
    }
    EXPECT_EQ(seen.size(), c.n * (c.n - 1) / 2);
  }
}

TEST(PairSchedule, BlocksAndGroupsAreNumberedConsistently) {
  for (const Case& c : OddCases()) {
    const std::vector<PairChunk> chunks = ScheduledPairChunks(Ids(c.n), c.block_size, c.blocks_per_group);
    if (chunks.empty()) continue;
    const int num_blocks = static_cast<int>((c.n + c.block_size - 1) / c.block_size);
    const int per_group = std::min(num_blocks, c.blocks_per_group);
    for (const PairChunk& chunk : chunks) {
      EXPECT_EQ(chunk.num_blocks, num_blocks);
      EXPECT_EQ(chunk.num_groups, (num_blocks + per_group - 1) / per_group);
      EXPECT_EQ(chunk.group_i, chunk.block_i / per_group);
      EXPECT_EQ(chunk.group_j, chunk.block_j / per_group);
    }
  }
}

// The matcher holds the blocks of the current and the next chunk; sharing a
// block between consecutive chunks keeps that to three blocks and makes each
// chunk load one block only.
TEST(PairSchedule, EachChunkBringsAtMostOneNewBlock) {
  for (const Case& c : OddCases()) {
    SCOPED_TRACE("n=" + std::to_string(c.n) + " block_size=" + std::to_string(c.block_size) +
                 " blocks_per_group=" + std::to_string(c.blocks_per_group));
    const std::vector<PairChunk> chunks = ScheduledPairChunks(Ids(c.n), c.block_size, c.blocks_per_group);
    for (size_t k = 1; k < chunks.size(); ++k) {
      EXPECT_LE(CountNew(BlocksOf(chunks[k]), BlocksOf(chunks[k - 1])), 1u) << "chunk " << k;
    }
  }
}

// Host memory holds the groups of the current group pair: each group pair
// after the first brings one new group at most, 1 + G(G-1)/2 loads in all,
// and each group's chunks are contiguous (a group pair is visited once).
TEST(PairSchedule, GroupLoadsAsPredicted) {
  for (const Case& c : OddCases()) {
    SCOPED_TRACE("n=" + std::to_string(c.n) + " block_size=" + std::to_string(c.block_size) +
                 " blocks_per_group=" + std::to_string(c.blocks_per_group));
    const std::vector<PairChunk> chunks = ScheduledPairChunks(Ids(c.n), c.block_size, c.blocks_per_group);
    if (chunks.empty()) continue;
    const size_t groups = static_cast<size_t>(chunks[0].num_groups);
    size_t loads = 0;
    std::set<int> held;
    std::set<std::pair<int, int>> finished;
    for (size_t k = 0; k < chunks.size(); ++k) {
      const std::pair<int, int> group_pair(chunks[k].group_i, chunks[k].group_j);
      if (k > 0 && group_pair != std::make_pair(chunks[k - 1].group_i, chunks[k - 1].group_j)) {
        EXPECT_TRUE(finished.insert({chunks[k - 1].group_i, chunks[k - 1].group_j}).second);
      }
      EXPECT_FALSE(finished.count(group_pair)) << "group pair visited twice";
      const std::set<int> now = GroupsOf(chunks[k]);
      loads += CountNew(now, held);
      held = now;
    }
    // A one-image last group has no diagonal chunk; it still comes once per
    // row, so the count is the same.
    EXPECT_EQ(loads, 1 + groups * (groups - 1) / 2);
  }
}

TEST(PairSchedule, SmallExampleOrder) {
  // 8 images, blocks of 2 (b0..b3), 2 blocks per group (G0 = b0 b1, G1 = b2 b3).
  const std::vector<PairChunk> chunks = ScheduledPairChunks(Ids(8), 2, 2);
  std::vector<std::pair<int, int>> order;
  for (const PairChunk& chunk : chunks) order.emplace_back(chunk.block_i, chunk.block_j);
  const std::vector<std::pair<int, int>> expected = {
      {0, 0}, {0, 1}, {1, 1},          // G0 x G0
      {1, 2}, {1, 3}, {0, 3}, {0, 2},  // G0 x G1, a snake starting on b1
      {2, 2}, {2, 3}, {3, 3}};         // G1 x G1 starting on b2
  EXPECT_EQ(order, expected);
}

// The run ends on chunks of blocks two or more apart, not on a diagonal one
// (the slowest to verify, and nothing hides the last chunks' verification).
TEST(PairSchedule, RunEndsOnBlocksTwoApart) {
  // 6 blocks in one group (300 images in blocks of 50).
  const std::vector<PairChunk> chunks = ScheduledPairChunks(Ids(12), 2, 6);
  std::vector<std::pair<int, int>> order;
  for (const PairChunk& chunk : chunks) order.emplace_back(chunk.block_i, chunk.block_j);
  const std::vector<std::pair<int, int>> expected = {
      {0, 0}, {0, 5}, {0, 4}, {0, 3}, {0, 2}, {0, 1}, {1, 1}, {1, 5}, {1, 4}, {1, 3}, {1, 2},
      {2, 2}, {2, 3}, {3, 3}, {3, 4}, {4, 4}, {4, 5}, {5, 5}, {3, 5}, {2, 5}, {2, 4}};
  EXPECT_EQ(order, expected);
  // Several groups: the last group pair ends the same way.
  for (const Case& c : OddCases()) {
    const std::vector<PairChunk> run = ScheduledPairChunks(Ids(c.n), c.block_size, c.blocks_per_group);
    if (run.empty()) continue;
    const int per_group = std::min(run[0].num_blocks, c.blocks_per_group);
    const int last_group_blocks = run[0].num_blocks - (run[0].num_groups - 1) * per_group;
    if (last_group_blocks < 3) continue;
    EXPECT_EQ(run.back().block_j - run.back().block_i, 2)
        << "n=" << c.n << " block_size=" << c.block_size << " blocks_per_group=" << c.blocks_per_group;
  }
}

}  // namespace
}  // namespace cashash
