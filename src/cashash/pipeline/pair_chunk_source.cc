#include "cashash/pipeline/pair_chunk_source.h"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

#include "cashash/base/pair_id.h"

namespace cashash {
namespace {

// FNV-1a, eight bytes at a time.
class Fnv {
 public:
  void Mix(uint64_t value) {
    for (int byte = 0; byte < 8; ++byte) {
      hash_ ^= (value >> (8 * byte)) & 0xff;
      hash_ *= 1099511628211ull;
    }
  }
  uint64_t value() const { return hash_; }

 private:
  uint64_t hash_ = 1469598103934665603ull;
};

}  // namespace

PairChunk PairChunkSource::Outline(size_t k) const {
  PairChunk chunk = Chunk(k);
  chunk.pairs = {};
  return chunk;
}

std::vector<PairChunk> AllChunks(const PairChunkSource& source) {
  std::vector<PairChunk> chunks;
  chunks.reserve(source.size());
  for (size_t k = 0; k < source.size(); ++k) chunks.push_back(source.Chunk(k));
  return chunks;
}

ChunkList::ChunkList(const std::vector<PairChunk>* chunks) : chunks_(chunks) {
  for (const PairChunk& chunk : *chunks_) num_pairs_ += chunk.pairs.size();
}

PairChunk ChunkList::Outline(size_t k) const {
  const PairChunk& full = (*chunks_)[k];
  PairChunk chunk;
  chunk.images = full.images;
  chunk.block_i = full.block_i;
  chunk.block_j = full.block_j;
  chunk.num_blocks = full.num_blocks;
  chunk.group_i = full.group_i;
  chunk.group_j = full.group_j;
  chunk.num_groups = full.num_groups;
  return chunk;
}

uint64_t ChunkList::Checksum() const {
  Fnv hash;
  for (const PairChunk& chunk : *chunks_) {
    hash.Mix(chunk.pairs.size());
    for (const ImagePair& pair : chunk.pairs) hash.Mix(ImagePairToPairId(pair.first, pair.second));
  }
  return hash.value();
}

ScheduledChunkSource::ScheduledChunkSource(std::vector<image_t> image_ids, int block_size, int blocks_per_group,
                                           PairTriangle done)
    : image_ids_(std::move(image_ids)), done_(std::move(done)) {
  const size_t n = image_ids_.size();
  if (!done_.empty() && done_.size() != n) {
    throw std::invalid_argument("completed pairs over " + std::to_string(done_.size()) + " images for a run over " +
                                std::to_string(n));
  }
  if (n < 2) return;
  block_size_ = static_cast<size_t>(std::max(1, block_size));
  num_blocks_ = static_cast<int>((n + block_size_ - 1) / block_size_);
  per_group_ = std::min(num_blocks_, std::max(1, blocks_per_group));
  num_groups_ = (num_blocks_ + per_group_ - 1) / per_group_;
  for (const auto& [bi, bj] : ScheduledBlockPairOrder(num_blocks_, per_group_)) {
    const size_t i_begin = bi * block_size_, i_end = std::min(n, i_begin + block_size_);
    const size_t j_begin = bj * block_size_, j_end = std::min(n, j_begin + block_size_);
    size_t pairs = 0;
    for (size_t i = i_begin; i < i_end; ++i) {
      const size_t from = std::max(j_begin, i + 1);
      if (from >= j_end) continue;
      pairs += (j_end - from) - done_.CountInRow(i, from, j_end);
    }
    if (pairs == 0) continue;
    order_.push_back(BlockPair{bi, bj, pairs});
    num_pairs_ += pairs;
  }
}

PairChunk ScheduledChunkSource::Make(size_t k, bool with_pairs) const {
  const BlockPair& block_pair = order_[k];
  const size_t n = image_ids_.size();
  PairChunk chunk;
  chunk.block_i = block_pair.block_i;
  chunk.block_j = block_pair.block_j;
  chunk.num_blocks = num_blocks_;
  chunk.group_i = block_pair.block_i / per_group_;
  chunk.group_j = block_pair.block_j / per_group_;
  chunk.num_groups = num_groups_;
  const size_t i_begin = block_pair.block_i * block_size_, i_end = std::min(n, i_begin + block_size_);
  const size_t j_begin = block_pair.block_j * block_size_, j_end = std::min(n, j_begin + block_size_);
  if (with_pairs) chunk.pairs.reserve(block_pair.num_pairs);
  // Positions that are in a pair left to match: all of both blocks unless
  // `done` left holes.
  std::vector<char> used_i(i_end - i_begin, done_.empty() ? 1 : 0), used_j(j_end - j_begin, done_.empty() ? 1 : 0);
  if (with_pairs || !done_.empty()) {
    for (size_t i = i_begin; i < i_end; ++i) {
      for (size_t j = std::max(j_begin, i + 1); j < j_end; ++j) {
        if (!Left(i, j)) continue;
        if (with_pairs) chunk.pairs.emplace_back(image_ids_[i], image_ids_[j]);
        used_i[i - i_begin] = 1;
        used_j[j - j_begin] = 1;
      }
    }
  }
  for (size_t i = i_begin; i < i_end; ++i) {
    if (used_i[i - i_begin]) chunk.images.push_back(image_ids_[i]);
  }
  for (size_t j = j_begin; j < j_end; ++j) {
    if (used_j[j - j_begin]) chunk.images.push_back(image_ids_[j]);
  }
  std::sort(chunk.images.begin(), chunk.images.end());
  chunk.images.erase(std::unique(chunk.images.begin(), chunk.images.end()), chunk.images.end());
  return chunk;
}

PairChunk ScheduledChunkSource::Chunk(size_t k) const { return Make(k, /*with_pairs=*/true); }

PairChunk ScheduledChunkSource::Outline(size_t k) const { return Make(k, /*with_pairs=*/false); }

uint64_t ScheduledChunkSource::Checksum() const {
  Fnv hash;
  hash.Mix(image_ids_.size());
  for (image_t id : image_ids_) hash.Mix(id);
  hash.Mix(block_size_);
  hash.Mix(static_cast<uint64_t>(per_group_));
  hash.Mix(order_.size());
  for (const BlockPair& block_pair : order_) {
    hash.Mix(static_cast<uint64_t>(block_pair.block_i));
    hash.Mix(static_cast<uint64_t>(block_pair.block_j));
    hash.Mix(block_pair.num_pairs);
  }
  for (uint64_t word : done_.words()) hash.Mix(word);
  return hash.value();
}

}  // namespace cashash
