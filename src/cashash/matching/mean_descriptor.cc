#include <cmath>

#include "cashash/matching/mean_descriptor.h"

namespace cashash {

// Exact integer sums, then rounded to the nearest integer: hashing subtracts
// the rounded mean (cascade_hashing.h), which keeps every hash an exact
// integer computation on every backend.
MeanDescriptor ComputeMeanDescriptor(const std::vector<const FeatureDescriptors*>& descriptors) {
  uint64_t sums[kDescriptorDim] = {};
  uint64_t num_rows = 0;
  for (const FeatureDescriptors* set : descriptors) {
    if (set == nullptr) continue;
    const size_t rows = set->rows();
    for (size_t i = 0; i < rows; ++i) {
      const uint8_t* row = set->row(i);
      for (int d = 0; d < kDescriptorDim; ++d) sums[d] += row[d];
    }
    num_rows += rows;
  }
  MeanDescriptor mean{};
  if (num_rows == 0) return mean;
  for (int d = 0; d < kDescriptorDim; ++d) {
    mean[d] = static_cast<float>(std::round(static_cast<double>(sums[d]) / num_rows));
  }
  return mean;
}

}  // namespace cashash
