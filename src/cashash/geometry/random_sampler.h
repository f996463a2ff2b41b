// Deterministic pseudo-random numbers and minimal-sample drawing for RANSAC.
// Every pair's verification is seeded from the options, so the same input and
// seed give the same geometry on any machine and thread schedule.
#pragma once

#include <cstddef>
#include <cstdint>

namespace cashash {

// SplitMix64: tiny state, passes BigCrush, and fast enough that sampling never
// shows up next to the model scoring.
class SplitMix64 {
 public:
  explicit SplitMix64(uint64_t seed) : state_(seed) {}

  uint64_t Next() {
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }

  // Uniform integer in [0, n) by a 64x64->128 multiply (bias below 2^-32 for
  // the point counts we see).
  uint32_t Below(uint32_t n) {
    return static_cast<uint32_t>((static_cast<unsigned __int128>(Next()) * n) >> 64);
  }

 private:
  uint64_t state_;
};

// Derives an independent stream seed from a base seed and a small tag, so the
// F, H, E and watermark estimators of one pair do not share random numbers.
inline uint64_t DeriveSeed(uint64_t base, uint64_t tag) {
  SplitMix64 mix(base ^ (tag * 0xD1B54A32D192ED03ULL));
  mix.Next();
  return mix.Next();
}

// Draws k distinct indices from [0, n) (k is tiny: 1 to 8), by rejection.
inline void SampleDistinct(SplitMix64& rng, uint32_t n, int k, int* out) {
  for (int i = 0; i < k; ++i) {
    for (;;) {
      const int candidate = static_cast<int>(rng.Below(n));
      bool taken = false;
      for (int j = 0; j < i; ++j) taken |= (out[j] == candidate);
      if (!taken) {
        out[i] = candidate;
        break;
      }
    }
  }
}

}  // namespace cashash
