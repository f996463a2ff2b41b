#include "cashash/pipeline/pair_generation.h"

#include <algorithm>
#include <unordered_set>

namespace cashash {
namespace {

void SortUnique(std::vector<image_t>* ids) {
  std::sort(ids->begin(), ids->end());
  ids->erase(std::unique(ids->begin(), ids->end()), ids->end());
}

// The chunk of block pair (bi, bj), bi <= bj: pairs (position i in bi,
// position j in bj, i < j). Empty for the diagonal pair of a one-image block.
PairChunk BlockPairChunk(const std::vector<image_t>& image_ids, size_t block_size, int bi, int bj) {
  const size_t n = image_ids.size();
  PairChunk chunk;
  chunk.block_i = bi;
  chunk.block_j = bj;
  const size_t i_begin = bi * block_size, i_end = std::min(n, i_begin + block_size);
  const size_t j_begin = bj * block_size, j_end = std::min(n, j_begin + block_size);
  for (size_t i = i_begin; i < i_end; ++i) {
    for (size_t j = std::max(j_begin, i + 1); j < j_end; ++j) {
      chunk.pairs.emplace_back(image_ids[i], image_ids[j]);
    }
  }
  if (chunk.pairs.empty()) return chunk;
  for (size_t i = i_begin; i < i_end; ++i) chunk.images.push_back(image_ids[i]);
  for (size_t j = j_begin; j < j_end; ++j) chunk.images.push_back(image_ids[j]);
  SortUnique(&chunk.images);
  return chunk;
}

// Orders block pairs group pair by group pair (see ScheduledPairChunks).
// `end_block` is the block the last emitted pair ended on, so that the next
// group pair can start there.
class BlockPairOrder {
 public:
  BlockPairOrder(int num_blocks, int blocks_per_group)
      : num_blocks_(num_blocks), per_group_(blocks_per_group) {}

  std::vector<std::pair<int, int>> Build() {
    const int num_groups = (num_blocks_ + per_group_ - 1) / per_group_;
    for (int gi = 0; gi < num_groups; ++gi) {
      Diagonal(gi, /*last=*/gi == num_groups - 1);
      for (int gk = num_groups - 1; gk > gi; --gk) Cross(gi, gk);
    }
    return order_;
  }

 private:
  std::vector<int> BlocksOf(int group) const {
    std::vector<int> blocks;
    for (int b = group * per_group_; b < std::min(num_blocks_, (group + 1) * per_group_); ++b) blocks.push_back(b);
    return blocks;
  }

  void Emit(int a, int b) {
    order_.emplace_back(std::min(a, b), std::max(a, b));
    end_block_ = b;
  }

  // Row r: (L[r], L[r]) then (L[r], L[c]) for c from the last down to r + 1,
  // so row r ends on L[r + 1], where row r + 1 starts. Starts on L[0]: the
  // list is reversed when the previous group pair ended on the last block.
  //
  // What a run waits for after its matching ends is the verification and
  // writing of its last chunks. A diagonal chunk, of neighbouring images
  // that mostly overlap, is the slowest to verify (0.3-0.37 s from start to
  // written at 300 images on the H200, against about 0.2 s for far chunks),
  // and the plain order ends on one. So the last group ends differently:
  // its last (up to) four blocks a b c d go as a band, then the far pairs,
  //   (a,a) (a,b) (b,b) (b,c) (c,c) (c,d) (d,d)  (b,d) (a,d) (a,c),
  // so that the last diagonal's verification runs while three far chunks
  // are matched. Each chunk still brings at most one block the one before
  // did not have, and the blocks uploaded are as many as in the plain order
  // (7 for the four).
  void Diagonal(int group, bool last) {
    std::vector<int> blocks = BlocksOf(group);
    if (end_block_ == blocks.back() && blocks.size() > 1) std::reverse(blocks.begin(), blocks.end());
    const int m = static_cast<int>(blocks.size());
    const int band_from = last && m >= 3 ? m - std::min(m, 4) : m;
    for (int r = 0; r < band_from; ++r) {
      Emit(blocks[r], blocks[r]);
      for (int c = m - 1; c > r; --c) Emit(blocks[r], blocks[c]);
    }
    if (band_from == m) return;
    for (int r = band_from; r < m; ++r) {
      Emit(blocks[r], blocks[r]);
      if (r + 1 < m) Emit(blocks[r], blocks[r + 1]);
    }
    const int a = band_from;
    if (m - a == 4) {
      Emit(blocks[a + 1], blocks[a + 3]);
      Emit(blocks[a], blocks[a + 3]);
    }
    Emit(blocks[a], blocks[a + 2]);
  }

  // Rows over gi's blocks, starting from the one the previous pair ended
  // on; each row walks gk's blocks, alternating direction (a snake). Ends
  // where the next group pair starts: on the last row's block when gi has
  // more cross pairs to go, on the last column's block before gk's diagonal.
  void Cross(int gi, int gk) {
    std::vector<int> rows = BlocksOf(gi);
    if (end_block_ != rows.front()) std::reverse(rows.begin(), rows.end());
    std::vector<int> columns = BlocksOf(gk);
    int last_column = columns.front();
    for (int row : rows) {
      for (int column : columns) {
        Emit(row, column);
        last_column = column;
      }
      std::reverse(columns.begin(), columns.end());
    }
    end_block_ = gk == gi + 1 ? last_column : rows.back();
  }

  int num_blocks_;
  int per_group_;
  int end_block_ = -1;
  std::vector<std::pair<int, int>> order_;
};

}  // namespace

std::vector<PairChunk> ExhaustivePairChunks(const std::vector<image_t>& image_ids, int block_size) {
  std::vector<PairChunk> chunks;
  const size_t n = image_ids.size();
  if (n < 2) return chunks;
  const size_t bs = static_cast<size_t>(std::max(1, block_size));
  const int num_blocks = static_cast<int>((n + bs - 1) / bs);
  for (int bi = 0; bi < num_blocks; ++bi) {
    for (int bj = bi; bj < num_blocks; ++bj) {
      PairChunk chunk = BlockPairChunk(image_ids, bs, bi, bj);
      if (chunk.pairs.empty()) continue;
      chunk.num_blocks = num_blocks;
      chunks.push_back(std::move(chunk));
    }
  }
  return chunks;
}

namespace {

// The chunks of block pairs `order` (bi <= bj), empty ones left out, with
// their block and group numbers (groups of per_group blocks).
std::vector<PairChunk> ChunksOfBlockPairs(const std::vector<image_t>& image_ids, size_t block_size, int num_blocks,
                                          int per_group, const std::vector<std::pair<int, int>>& order) {
  std::vector<PairChunk> chunks;
  const int num_groups = (num_blocks + per_group - 1) / per_group;
  for (const auto& [bi, bj] : order) {
    PairChunk chunk = BlockPairChunk(image_ids, block_size, bi, bj);
    if (chunk.pairs.empty()) continue;
    chunk.num_blocks = num_blocks;
    chunk.group_i = bi / per_group;
    chunk.group_j = bj / per_group;
    chunk.num_groups = num_groups;
    chunks.push_back(std::move(chunk));
  }
  return chunks;
}

}  // namespace

std::vector<PairChunk> ScheduledPairChunks(const std::vector<image_t>& image_ids, int block_size,
                                           int blocks_per_group) {
  const size_t n = image_ids.size();
  if (n < 2) return {};
  const size_t bs = static_cast<size_t>(std::max(1, block_size));
  const int num_blocks = static_cast<int>((n + bs - 1) / bs);
  const int per_group = std::min(num_blocks, std::max(1, blocks_per_group));
  return ChunksOfBlockPairs(image_ids, bs, num_blocks, per_group, BlockPairOrder(num_blocks, per_group).Build());
}

std::vector<std::pair<int, int>> ScheduledBlockPairOrder(int num_blocks, int blocks_per_group) {
  if (num_blocks < 1) return {};
  const int per_group = std::min(num_blocks, std::max(1, blocks_per_group));
  return BlockPairOrder(num_blocks, per_group).Build();
}

std::vector<PairChunk> ListPairChunks(const std::vector<ImagePair>& pairs, size_t max_pairs_per_chunk,
                                      size_t max_images_per_chunk) {
  std::vector<PairChunk> chunks;
  PairChunk current;
  std::unordered_set<image_t> current_images;
  auto flush = [&]() {
    if (current.pairs.empty()) return;
    current.images.assign(current_images.begin(), current_images.end());
    SortUnique(&current.images);
    chunks.push_back(std::move(current));
    current = PairChunk();
    current_images.clear();
  };
  for (const ImagePair& pair : pairs) {
    const size_t new_images = (current_images.count(pair.first) ? 0 : 1) +
                              (current_images.count(pair.second) ? 0 : 1);
    if (current.pairs.size() >= max_pairs_per_chunk ||
        (!current.pairs.empty() && current_images.size() + new_images > max_images_per_chunk)) {
      flush();
    }
    current.pairs.push_back(pair);
    current_images.insert(pair.first);
    current_images.insert(pair.second);
  }
  flush();
  const int n = static_cast<int>(chunks.size());
  for (int i = 0; i < n; ++i) {
    chunks[i].block_i = i;
    chunks[i].block_j = i;
    chunks[i].num_blocks = n;
  }
  return chunks;
}

}  // namespace cashash
