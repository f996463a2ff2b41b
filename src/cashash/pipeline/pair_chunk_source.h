// The chunks of a run, made when the pipeline asks for them. An exhaustive
// run over n images has n(n-1)/2 pairs (200 million at 20,000 images, 1.6
// GB as a list), but a chunk is fully determined by its pair of image
// blocks: ScheduledChunkSource keeps the order of the block pairs and makes
// a chunk's pairs on demand, so that host memory does not grow with the
// pairs. Pair lists (ListPairChunks) are as large as the list given, and
// are held as they are (ChunkList).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "cashash/pipeline/pair_generation.h"
#include "cashash/pipeline/pair_triangle.h"

namespace cashash {

class PairChunkSource {
 public:
  virtual ~PairChunkSource() = default;
  // Chunks, none of them empty.
  virtual size_t size() const = 0;
  // Pairs of every chunk.
  virtual size_t num_pairs() const = 0;
  // Pairs of chunk k, without making it.
  virtual size_t NumPairs(size_t k) const = 0;
  // Chunk k < size(): pairs, images and block and group numbers. Const
  // calls may come from several threads at once.
  virtual PairChunk Chunk(size_t k) const = 0;
  // Chunk k without its pairs (images, block and group numbers): what the
  // feature cache plans with, cheaper than Chunk.
  virtual PairChunk Outline(size_t k) const;
  // Equal for sources that yield the same chunks; computed without making
  // every chunk where the source can (MPI ranks compare it).
  virtual uint64_t Checksum() const = 0;
};

// Every chunk of `source` (pairs and all), for tests and small runs.
std::vector<PairChunk> AllChunks(const PairChunkSource& source);

// Chunks held in memory by the caller (not owned: the vector must outlive
// this view).
class ChunkList : public PairChunkSource {
 public:
  explicit ChunkList(const std::vector<PairChunk>* chunks);
  size_t size() const override { return chunks_->size(); }
  size_t num_pairs() const override { return num_pairs_; }
  size_t NumPairs(size_t k) const override { return (*chunks_)[k].pairs.size(); }
  PairChunk Chunk(size_t k) const override { return (*chunks_)[k]; }
  PairChunk Outline(size_t k) const override;
  // FNV-1a over the chunk sizes and pair ids, in order.
  uint64_t Checksum() const override;

 private:
  const std::vector<PairChunk>* chunks_;
  size_t num_pairs_ = 0;
};

// The chunks of ScheduledPairChunks(image_ids, block_size,
// blocks_per_group), in the same order with the same pairs, images and
// numbers, made one at a time. Pairs set in `done` (positions in
// image_ids: the pairs a resumed run already has) are left out, and chunks
// left empty are dropped, as RemovePairs does. Holds the image ids, the
// non-empty block pairs in order with their pair counts (16 bytes each:
// 1.3 MB at 20,000 images in blocks of 50) and `done`.
class ScheduledChunkSource : public PairChunkSource {
 public:
  // Throws std::invalid_argument when `done` is not over image_ids.size()
  // positions.
  ScheduledChunkSource(std::vector<image_t> image_ids, int block_size, int blocks_per_group,
                       PairTriangle done = PairTriangle());

  size_t size() const override { return order_.size(); }
  size_t num_pairs() const override { return num_pairs_; }
  size_t NumPairs(size_t k) const override { return order_[k].num_pairs; }
  PairChunk Chunk(size_t k) const override;
  PairChunk Outline(size_t k) const override;
  // Over the image ids, the sizes, the block pairs with their pair counts
  // and the bits of `done`: O(chunks + n^2/64), never every pair.
  uint64_t Checksum() const override;

 private:
  struct BlockPair {
    int block_i = 0;
    int block_j = 0;
    size_t num_pairs = 0;  // left after `done`
  };
  // Chunk k with its numbers, images and, when asked, pairs.
  PairChunk Make(size_t k, bool with_pairs) const;
  // Whether pair (i, j) of positions is left to match.
  bool Left(size_t i, size_t j) const { return done_.empty() || !done_.Test(i, j); }

  std::vector<image_t> image_ids_;
  size_t block_size_ = 1;
  int num_blocks_ = 0;
  int per_group_ = 1;
  int num_groups_ = 0;
  PairTriangle done_;
  std::vector<BlockPair> order_;
  size_t num_pairs_ = 0;
};

}  // namespace cashash
