// Resume bookkeeping that stays small at any database size: which pairs of
// a run the database already holds, one bit per pair of the run.
//
// An exhaustive run over n images keeps n(n-1)/2 bits (20,000 images, 200
// million pairs: 25 MiB), once the database holds one of its pairs; a pair
// list keeps its own pairs sorted (8 bytes each, as the list itself) and
// one bit for each. The smaller of the two is used. Completed pairs of the
// database that the run does not ask for cost nothing: they are streamed
// from SQLite, never collected.
#pragma once

#include <cstddef>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

#include "cashash/pipeline/pair_generation.h"
#include "cashash/pipeline/pair_triangle.h"
#include "cashash/base/types.h"

namespace cashash {
namespace colmap {

class Database;

class CompletedPairs {
 public:
  // Nothing completed yet, for the pairs of `chunks` among `image_ids`
  // (every image of a pair must be in image_ids).
  CompletedPairs(const std::vector<image_t>& image_ids, const std::vector<PairChunk>& chunks);
  // Nothing completed yet, for every pair of `image_ids` (an exhaustive run).
  explicit CompletedPairs(const std::vector<image_t>& image_ids);

  // Marks a pair completed; pairs the run does not hold are ignored.
  void Mark(pair_t pair_id);
  bool Contains(image_t image_id1, image_t image_id2) const;

  size_t num_completed() const { return num_completed_; }
  // Heap bytes held (the figure the design above promises).
  size_t memory_bytes() const;
  bool uses_image_triangle() const { return triangle_; }
  // The completed pairs by their positions in image_ids (the image
  // triangle only), handed over: what ScheduledChunkSource leaves out.
  PairTriangle TakeTriangle() { return std::move(triangle_bits_); }

 private:
  void IndexImages(const std::vector<image_t>& image_ids);
  // Bit of a pair of a list run, or -1.
  int64_t BitOf(image_t image_id1, image_t image_id2) const;
  int64_t IndexOfImage(image_t image_id) const;

  bool triangle_ = true;
  uint64_t num_images_ = 0;
  // Image id -> position, dense when ids are (COLMAP numbers them 1..n).
  std::vector<uint32_t> dense_index_;
  std::unordered_map<image_t, uint32_t> sparse_index_;
  PairTriangle triangle_bits_;        // triangle mode
  std::vector<pair_t> sorted_pairs_;  // list mode, with bits_
  std::vector<uint64_t> bits_;
  size_t num_completed_ = 0;
};

// The pairs of `chunks` that `database` holds as completed (rows in both
// matches and two_view_geometries, or recorded as empty), read as a stream.
CompletedPairs ReadCompletedPairs(const Database& database, const std::vector<image_t>& image_ids,
                                  const std::vector<PairChunk>& chunks);
// The same for every pair of `image_ids`.
CompletedPairs ReadCompletedPairs(const Database& database, const std::vector<image_t>& image_ids);

}  // namespace colmap
}  // namespace cashash
