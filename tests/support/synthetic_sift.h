// SIFT-like random descriptors for the matcher tests: sparse non-negative
// values scaled to norm ~512 and capped at 255, as COLMAP stores SIFT.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "cashash/base/types.h"

namespace cashash {
namespace testing_support {

inline std::vector<uint8_t> RandomSift(std::mt19937* rng) {
  std::exponential_distribution<double> value(1.0);
  std::vector<double> v(kDescriptorDim);
  double norm = 0;
  for (double& x : v) {
    x = value(*rng);
    x *= x;
    norm += x * x;
  }
  std::vector<uint8_t> out(kDescriptorDim);
  for (int d = 0; d < kDescriptorDim; ++d) {
    out[d] = static_cast<uint8_t>(std::min(255.0, std::round(512.0 * v[d] / std::sqrt(norm))));
  }
  return out;
}

}  // namespace testing_support
}  // namespace cashash
