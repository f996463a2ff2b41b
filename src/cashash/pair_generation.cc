#include "cashash/pair_generation.h"

#include <algorithm>
#include <unordered_set>

namespace cashash {
namespace {

void SortUnique(std::vector<image_t>* ids) {
  std::sort(ids->begin(), ids->end());
  ids->erase(std::unique(ids->begin(), ids->end()), ids->end());
}

}  // namespace

std::vector<PairChunk> ExhaustivePairChunks(const std::vector<image_t>& image_ids, int block_size) {
  std::vector<PairChunk> chunks;
  const size_t n = image_ids.size();
  if (n < 2) return chunks;
  const size_t bs = static_cast<size_t>(std::max(1, block_size));
  const int num_blocks = static_cast<int>((n + bs - 1) / bs);
  for (int bi = 0; bi < num_blocks; ++bi) {
    for (int bj = bi; bj < num_blocks; ++bj) {
      PairChunk chunk;
      chunk.block_i = bi;
      chunk.block_j = bj;
      chunk.num_blocks = num_blocks;
      const size_t i_begin = bi * bs, i_end = std::min(n, i_begin + bs);
      const size_t j_begin = bj * bs, j_end = std::min(n, j_begin + bs);
      for (size_t i = i_begin; i < i_end; ++i) {
        for (size_t j = std::max(j_begin, i + 1); j < j_end; ++j) {
          chunk.pairs.emplace_back(image_ids[i], image_ids[j]);
        }
      }
      if (chunk.pairs.empty()) continue;
      for (size_t i = i_begin; i < i_end; ++i) chunk.images.push_back(image_ids[i]);
      for (size_t j = j_begin; j < j_end; ++j) chunk.images.push_back(image_ids[j]);
      SortUnique(&chunk.images);
      chunks.push_back(std::move(chunk));
    }
  }
  return chunks;
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
