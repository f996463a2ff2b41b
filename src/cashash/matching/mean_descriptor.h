// The global mean descriptor subtracted before hashing (zero-mean hashing, as
// the original CasHash). Computed once per run over the images to match.
#pragma once

#include <array>
#include <vector>

#include "cashash/base/types.h"

namespace cashash {

using MeanDescriptor = std::array<float, kDescriptorDim>;

// Mean of all descriptor rows of the given sets (uint8 -> float), rounded to
// the nearest integer so that hashing stays exact integer arithmetic in every
// backend (cascade_hashing.h, step 1).
MeanDescriptor ComputeMeanDescriptor(const std::vector<const FeatureDescriptors*>& descriptors);

}  // namespace cashash
