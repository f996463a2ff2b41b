// Which image pairs to match, and in what order. Exhaustive matching walks
// blocks of images as COLMAP's ExhaustiveMatching.block_size does, so that
// only two blocks of features need to be loaded at a time. The scheduled
// order adds a second level, groups of blocks (what host memory holds), as
// the three-level data scheduling of Xu, Sun and Tao: see
// ScheduledPairChunks.
#pragma once

#include <utility>
#include <vector>

#include "cashash/base/pair_id.h"
#include "cashash/base/types.h"

namespace cashash {

// A chunk of pairs matched together; images() are the images they touch.
struct PairChunk {
  std::vector<ImagePair> pairs;
  std::vector<image_t> images;  // sorted, unique
  int block_i = 0;              // for progress messages: block indices
  int block_j = 0;
  int num_blocks = 0;
  int group_i = 0;  // groups of blocks holding block_i and block_j
  int group_j = 0;
  int num_groups = 1;
};

// Every unordered pair of `image_ids` once, as (smaller position, larger
// position) in the given order, grouped by block pairs (i <= j).
std::vector<PairChunk> ExhaustivePairChunks(const std::vector<image_t>& image_ids, int block_size);

// Every unordered pair of `image_ids` once, like ExhaustivePairChunks, one
// chunk per pair of blocks, but in an order that reloads as little as
// possible when blocks (block_size images, what the matcher holds) are
// gathered into groups (blocks_per_group blocks, what host memory holds).
//
// Group pairs come as (G0,G0), (G0,Gn-1), ..., (G0,G1), (G1,G1), (G1,Gn-1),
// ..., so that each group pair after the first brings exactly one group not
// already held (none for a diagonal one): 1 + n(n-1)/2 group loads in all.
// Inside a group pair the block pairs are ordered the same way (diagonal
// pairs in a row first, then the rest of the row from the far end; across
// two groups a snake), and each group pair starts on a block the previous
// one ended on, so every chunk after the first shares a block with the one
// before it: the matcher never needs more than three blocks at once. The
// last group's last four blocks go as a band, then their far pairs, so
// that the run does not end on a diagonal chunk, the slowest to verify
// (see BlockPairOrder::Diagonal).
//
// This list holds every pair (1.6 GB at 20,000 images); a run makes the
// same chunks one at a time instead (ScheduledChunkSource,
// pair_chunk_source.h).
std::vector<PairChunk> ScheduledPairChunks(const std::vector<image_t>& image_ids, int block_size,
                                           int blocks_per_group);

// The block pairs (bi <= bj) of ScheduledPairChunks in its order, empty
// ones (the diagonal of a one-image block) included.
std::vector<std::pair<int, int>> ScheduledBlockPairOrder(int num_blocks, int blocks_per_group);

// Splits an arbitrary pair list into chunks of at most max_pairs_per_chunk
// pairs (in the given order), each touching at most max_images_per_chunk
// images where possible.
std::vector<PairChunk> ListPairChunks(const std::vector<ImagePair>& pairs, size_t max_pairs_per_chunk,
                                      size_t max_images_per_chunk);

}  // namespace cashash

namespace cashash {

// Removes the pairs for which skip(pair) is true (e.g. pairs already in the
// database when resuming), dropping chunks left empty and recomputing the
// images each chunk touches.
template <typename SkipPredicate>
std::vector<PairChunk> RemovePairs(std::vector<PairChunk> chunks, SkipPredicate skip);

}  // namespace cashash

#include <algorithm>

namespace cashash {

template <typename SkipPredicate>
std::vector<PairChunk> RemovePairs(std::vector<PairChunk> chunks, SkipPredicate skip) {
  std::vector<PairChunk> kept;
  for (PairChunk& chunk : chunks) {
    std::vector<ImagePair> pairs;
    for (const ImagePair& pair : chunk.pairs) {
      if (!skip(pair)) pairs.push_back(pair);
    }
    if (pairs.empty()) continue;
    chunk.images = ImagesOfPairs(pairs);
    chunk.pairs = std::move(pairs);
    kept.push_back(std::move(chunk));
  }
  return kept;
}

}  // namespace cashash
