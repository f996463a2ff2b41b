// The retrieval that loop detection asks for the images most like a query
// image (sequential_matcher's SequentialMatching.loop_detection). An
// interface, so that pair generation knows no index: an implementation
// builds its index from the database's own features.
#pragma once

#include <vector>

#include "cashash/base/types.h"

namespace cashash {

class ImageRetrieval {
 public:
  virtual ~ImageRetrieval() = default;

  // For each query image, the ids of at most `num_images` other images of
  // the collection most like it, most similar first (the query itself left
  // out). One call for all queries, so that an implementation may search
  // them together (on the GPU).
  virtual std::vector<std::vector<image_t>> MostSimilarImages(const std::vector<image_t>& query_image_ids,
                                                              int num_images) = 0;
};

}  // namespace cashash
