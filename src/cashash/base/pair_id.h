// COLMAP's pair identifiers: pair_id = 2147483647 * min(id1, id2) + max(id1, id2).
#pragma once

#include <algorithm>
#include <utility>
#include <vector>

#include "cashash/base/types.h"

namespace cashash {

constexpr uint64_t kMaxNumImages = 2147483647ull;

inline pair_t ImagePairToPairId(image_t image_id1, image_t image_id2) {
  if (image_id1 > image_id2) std::swap(image_id1, image_id2);
  return kMaxNumImages * image_id1 + image_id2;
}

inline ImagePair PairIdToImagePair(pair_t pair_id) {
  const image_t image_id2 = static_cast<image_t>(pair_id % kMaxNumImages);
  const image_t image_id1 = static_cast<image_t>((pair_id - image_id2) / kMaxNumImages);
  return {image_id1, image_id2};
}

// True when a pair must be stored swapped (COLMAP keys pairs by the smaller id first).
inline bool SwapImagePair(image_t image_id1, image_t image_id2) { return image_id1 > image_id2; }

// The images the pairs name, sorted, each once.
inline std::vector<image_t> ImagesOfPairs(const std::vector<ImagePair>& pairs) {
  std::vector<image_t> image_ids;
  image_ids.reserve(2 * pairs.size());
  for (const ImagePair& pair : pairs) {
    image_ids.push_back(pair.first);
    image_ids.push_back(pair.second);
  }
  std::sort(image_ids.begin(), image_ids.end());
  image_ids.erase(std::unique(image_ids.begin(), image_ids.end()), image_ids.end());
  return image_ids;
}

}  // namespace cashash
