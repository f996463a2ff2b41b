#include "colmap_bridge/completed_pairs.h"

#include <algorithm>
#include <limits>

#include "cashash/base/pair_id.h"
#include "colmap_bridge/database.h"

namespace cashash {
namespace colmap {
namespace {

constexpr uint32_t kNoIndex = std::numeric_limits<uint32_t>::max();

}  // namespace

CompletedPairs::CompletedPairs(const std::vector<image_t>& image_ids, const std::vector<PairChunk>& chunks) {
  num_images_ = image_ids.size();
  size_t num_pairs = 0;
  for (const PairChunk& chunk : chunks) num_pairs += chunk.pairs.size();
  const uint64_t triangle_pairs = num_images_ * (num_images_ > 0 ? num_images_ - 1 : 0) / 2;
  // Triangle: 1 bit per pair of the images; list: 64 + 1 bits per pair asked for.
  triangle_ = triangle_pairs <= 65 * static_cast<uint64_t>(num_pairs);
  if (triangle_) {
    IndexImages(image_ids);
    triangle_bits_ = PairTriangle(num_images_);
  } else {
    sorted_pairs_.reserve(num_pairs);
    for (const PairChunk& chunk : chunks) {
      for (const ImagePair& pair : chunk.pairs) sorted_pairs_.push_back(ImagePairToPairId(pair.first, pair.second));
    }
    std::sort(sorted_pairs_.begin(), sorted_pairs_.end());
    sorted_pairs_.erase(std::unique(sorted_pairs_.begin(), sorted_pairs_.end()), sorted_pairs_.end());
    sorted_pairs_.shrink_to_fit();
    bits_.assign((sorted_pairs_.size() + 63) / 64, 0);
  }
}

CompletedPairs::CompletedPairs(const std::vector<image_t>& image_ids)
    : triangle_(true), num_images_(image_ids.size()), triangle_bits_(image_ids.size()) {
  IndexImages(image_ids);
}

void CompletedPairs::IndexImages(const std::vector<image_t>& image_ids) {
  image_t max_id = 0;
  for (image_t id : image_ids) max_id = std::max(max_id, id);
  if (static_cast<uint64_t>(max_id) <= 4 * num_images_ + 1024) {
    dense_index_.assign(static_cast<size_t>(max_id) + 1, kNoIndex);
    for (size_t i = 0; i < image_ids.size(); ++i) dense_index_[image_ids[i]] = static_cast<uint32_t>(i);
  } else {
    for (size_t i = 0; i < image_ids.size(); ++i) sparse_index_.emplace(image_ids[i], static_cast<uint32_t>(i));
  }
}

int64_t CompletedPairs::IndexOfImage(image_t image_id) const {
  if (!dense_index_.empty() || sparse_index_.empty()) {
    if (image_id >= dense_index_.size()) return -1;
    const uint32_t index = dense_index_[image_id];
    return index == kNoIndex ? -1 : static_cast<int64_t>(index);
  }
  const auto it = sparse_index_.find(image_id);
  return it == sparse_index_.end() ? -1 : static_cast<int64_t>(it->second);
}

int64_t CompletedPairs::BitOf(image_t image_id1, image_t image_id2) const {
  const pair_t pair_id = ImagePairToPairId(image_id1, image_id2);
  const auto it = std::lower_bound(sorted_pairs_.begin(), sorted_pairs_.end(), pair_id);
  if (it == sorted_pairs_.end() || *it != pair_id) return -1;
  return it - sorted_pairs_.begin();
}

void CompletedPairs::Mark(pair_t pair_id) {
  const ImagePair pair = PairIdToImagePair(pair_id);
  if (triangle_) {
    const int64_t i = IndexOfImage(pair.first), j = IndexOfImage(pair.second);
    if (i < 0 || j < 0 || i == j) return;
    if (triangle_bits_.Set(static_cast<size_t>(i), static_cast<size_t>(j))) ++num_completed_;
    return;
  }
  const int64_t bit = BitOf(pair.first, pair.second);
  if (bit < 0) return;
  uint64_t& word = bits_[static_cast<size_t>(bit) / 64];
  const uint64_t mask = uint64_t{1} << (bit % 64);
  if (word & mask) return;
  word |= mask;
  ++num_completed_;
}

bool CompletedPairs::Contains(image_t image_id1, image_t image_id2) const {
  if (triangle_) {
    const int64_t i = IndexOfImage(image_id1), j = IndexOfImage(image_id2);
    return i >= 0 && j >= 0 && i != j && triangle_bits_.Test(static_cast<size_t>(i), static_cast<size_t>(j));
  }
  const int64_t bit = BitOf(image_id1, image_id2);
  return bit >= 0 && (bits_[static_cast<size_t>(bit) / 64] >> (bit % 64)) & 1;
}

size_t CompletedPairs::memory_bytes() const {
  return triangle_bits_.memory_bytes() + bits_.capacity() * sizeof(uint64_t) +
         sorted_pairs_.capacity() * sizeof(pair_t) + dense_index_.capacity() * sizeof(uint32_t) +
         sparse_index_.size() * (sizeof(image_t) + sizeof(uint32_t) + 2 * sizeof(void*));
}

CompletedPairs ReadCompletedPairs(const Database& database, const std::vector<image_t>& image_ids,
                                  const std::vector<PairChunk>& chunks) {
  CompletedPairs completed(image_ids, chunks);
  database.ForEachCompletedPairId([&](pair_t pair_id) { completed.Mark(pair_id); });
  return completed;
}

CompletedPairs ReadCompletedPairs(const Database& database, const std::vector<image_t>& image_ids) {
  CompletedPairs completed(image_ids);
  database.ForEachCompletedPairId([&](pair_t pair_id) { completed.Mark(pair_id); });
  return completed;
}

}  // namespace colmap
}  // namespace cashash
