#include "cashash/retrieval/retrieval_options.h"

#include <algorithm>
#include <cmath>

namespace cashash {

std::string RetrievalOptions::Check() const {
  if (num_images < 1) return "--VocabTreeMatching.num_images must be >= 1, got " + std::to_string(num_images);
  if (num_nearest_neighbors < 1 || num_nearest_neighbors > kMaxNearestNeighbors) {
    return "--VocabTreeMatching.num_nearest_neighbors must be in [1, " + std::to_string(kMaxNearestNeighbors) +
           "], got " +
           std::to_string(num_nearest_neighbors);
  }
  if (max_num_features == 0 || max_num_features < -1) {
    return "--VocabTreeMatching.max_num_features must be -1 (all) or >= 1, got " + std::to_string(max_num_features);
  }
  if (num_tables < 1 || num_tables > kMaxTables) {
    return "--Retrieval.num_tables must be in [1, " + std::to_string(kMaxTables) + "], got " +
           std::to_string(num_tables);
  }
  if (bits_per_word != 0 && (bits_per_word < kMinBitsPerWord || bits_per_word > kMaxBitsPerWord)) {
    return "--Retrieval.bits_per_word must be 0 (from the features per image) or in [" +
           std::to_string(kMinBitsPerWord) + ", " + std::to_string(kMaxBitsPerWord) + "], got " +
           std::to_string(bits_per_word);
  }
  if (!(max_word_image_fraction > 0.0 && max_word_image_fraction <= 1.0)) {
    return "--Retrieval.max_word_image_fraction must be in (0, 1], got " + std::to_string(max_word_image_fraction);
  }
  return "";
}

int RetrievalBitsPerWord(const RetrievalOptions& options, size_t features_per_image) {
  if (options.bits_per_word > 0) return options.bits_per_word;
  int log2_features = 0;
  while ((size_t{1} << (log2_features + 1)) <= std::max<size_t>(features_per_image, 1)) ++log2_features;
  return std::clamp(log2_features + 10, RetrievalOptions::kMinBitsPerWord, RetrievalOptions::kMaxBitsPerWord);
}

}  // namespace cashash
