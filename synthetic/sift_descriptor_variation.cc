#include "synthetic/sift_descriptor_variation.h"

#include <algorithm>
#include <cmath>

namespace cashash {
namespace colmap {
namespace {

// Standard normal quantiles at (i + 0.5) / 256: one random byte gives one
// Gaussian value, cheaply enough for 20,000 images of 8,192 descriptors.
std::array<float, 256> MakeGaussianTable() {
  std::array<float, 256> table{};
  for (int i = 0; i < 256; ++i) {
    const double p = (i + 0.5) / 256.0;
    // Bisection on the normal CDF 0.5 * erfc(-x / sqrt(2)).
    double low = -10, high = 10;
    for (int step = 0; step < 100; ++step) {
      const double mid = 0.5 * (low + high);
      (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p ? low : high) = mid;
    }
    table[i] = static_cast<float>(0.5 * (low + high));
  }
  return table;
}

}  // namespace

DescriptorPermutation RandomDescriptorPermutation(uint64_t seed) {
  DescriptorPermutation permutation;
  for (int d = 0; d < kDescriptorDim; ++d) permutation[d] = static_cast<uint8_t>(d);
  SplitMix64 rng(seed);
  for (int d = kDescriptorDim; d > 1; --d) std::swap(permutation[d - 1], permutation[rng.Below(d)]);
  return permutation;
}

void PerturbSiftDescriptor(const uint8_t* in, const DescriptorPermutation& permutation, double sigma,
                           SplitMix64& rng, uint8_t* out) {
  static const std::array<float, 256> gaussian = MakeGaussianTable();
  float values[kDescriptorDim];
  double squared_norm = 0;
  const float scale = static_cast<float>(sigma);
  for (int d = 0; d < kDescriptorDim; d += 8) {
    uint64_t bytes = rng.Next();
    for (int k = 0; k < 8; ++k, bytes >>= 8) {
      const float v = std::max(0.f, static_cast<float>(in[permutation[d + k]]) + scale * gaussian[bytes & 0xFF]);
      values[d + k] = v;
      squared_norm += static_cast<double>(v) * v;
    }
  }
  const float to_stored = squared_norm > 0 ? static_cast<float>(512.0 / std::sqrt(squared_norm)) : 0.f;
  for (int d = 0; d < kDescriptorDim; ++d) {
    out[d] = static_cast<uint8_t>(std::min(255.f, std::round(values[d] * to_stored)));
  }
}

}  // namespace colmap
}  // namespace cashash
