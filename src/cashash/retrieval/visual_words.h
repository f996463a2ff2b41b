// Visual words from the cascade's kind of hash codes: the sign bits of
// random projections of (descriptor - mean descriptor), as cascade hashing
// computes them (cascade_hashing.h, steps 1 to 3), cut into words of
// bits_per_word bits, one per table. A word is a cell of a random
// hyperplane partition of descriptor space: two views of one 3D point
// fall in the same cell of a table with probability (1 - angle / pi)^bits,
// unrelated features with about 2^-bits. Nothing is trained: the
// projections come from the seed, the mean from the run's own images.
#pragma once

#include <cstdint>
#include <vector>

#include "cashash/base/types.h"
#include "cashash/matching/mean_descriptor.h"
#include "cashash/retrieval/retrieval_options.h"

namespace cashash {

// The words of one image. Word ids are table * 2^bits_per_word + cell, so
// the tables share one vocabulary of num_tables * 2^bits_per_word words.
struct ImageWords {
  // One word per feature and table: the cell the feature lies in. What
  // the index stores.
  std::vector<uint32_t> indexed;
  // The cells a query of this image looks up: for each feature and table
  // its own cell and its num_nearest_neighbors - 1 nearest cells (across
  // the bits whose projections lie closest to zero). Empty when
  // num_nearest_neighbors is 1: the query words are then `indexed`.
  std::vector<uint32_t> query;
};

class VisualWordHasher {
 public:
  // Throws std::invalid_argument for options that fail Check() or
  // bits_per_word outside [kMinBitsPerWord, kMaxBitsPerWord].
  VisualWordHasher(const RetrievalOptions& options, int bits_per_word, const MeanDescriptor& mean);

  // Words of the given rows of `descriptors` (all rows when `rows` is
  // empty); rows past the descriptors' end are an error.
  ImageWords Words(const FeatureDescriptors& descriptors, const std::vector<uint32_t>& rows = {}) const;

  int num_tables() const { return num_tables_; }
  int bits_per_word() const { return bits_per_word_; }
  uint32_t vocabulary_size() const { return static_cast<uint32_t>(num_tables_) << bits_per_word_; }

 private:
  int num_tables_ = 0;
  int bits_per_word_ = 0;
  int num_probes_ = 1;
  // (num_tables * bits_per_word) x 128 integer entries as floats, row-major.
  std::vector<float> rows_;
  std::vector<float> row_norms_;
  std::vector<float> rounded_mean_;
};

// The cells nearest to a feature's own in one table, as bit masks to XOR
// into its cell: the num_probes - 1 flip sets of least total squared
// margin, where margins[i] >= 0 is the distance of the feature to the
// hyperplane of bit i (query-directed multi-probe LSH, Lv et al. 2007).
// Considers flips of single bits and of two bits among the four least
// certain, which holds the nearest cells for num_probes <= 5.
std::vector<uint32_t> NearestCellFlips(const float* margins, int bits, int num_probes);
// The same into masks[0 .. returned count), at most kMaxCellFlips.
constexpr int kMaxCellFlips = 10;
int NearestCellFlips(const float* margins, int bits, int num_probes, uint32_t* masks);

}  // namespace cashash
