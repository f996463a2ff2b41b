// New SIFT descriptors from real ones, for generated databases: unrelated
// "scenes" made from one source, and the noise that another view of the
// same point adds.
#pragma once

#include <array>
#include <cstdint>

#include "cashash/geometry/random_sampler.h"
#include "cashash/base/types.h"

namespace cashash {
namespace colmap {

// out[d] = in[permutation[d]].
using DescriptorPermutation = std::array<uint8_t, kDescriptorDim>;

// A random reordering of the 128 values. Descriptors of one photograph set
// resemble each other (a building repeats its windows): unrelated images cut
// from one source would match each other about ten times as often as
// unrelated photographs do. Reordering every descriptor of a stretch of
// scene alike keeps the values, norms and all distances within the stretch
// as the real ones, while stretches with different orders stop resembling
// each other.
DescriptorPermutation RandomDescriptorPermutation(uint64_t seed);

// The permuted `in` plus Gaussian noise of `sigma` (stored uint8 units) on
// every value, clamped at zero and stored as COLMAP stores SIFT: L2 norm
// scaled to 512, rounded, capped at 255.
void PerturbSiftDescriptor(const uint8_t* in, const DescriptorPermutation& permutation, double sigma,
                           SplitMix64& rng, uint8_t* out);

}  // namespace colmap
}  // namespace cashash
