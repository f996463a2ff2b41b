// GPU parts of Ga-CasHash (cashash/guided_matching.h): the stage-1 F
// estimation by the batched GPU RANSAC. Stage 2 is the GPU cascade matcher's
// MatchPairsGuided (CreateGpuFeatureMatcher).
#pragma once

#include <memory>

#include "cashash/matching/guided_matching.h"

namespace cashash {
namespace cuda {

// F of every pair of a batch in one launch (GpuTwoViewRansac; its H
// estimates are dropped). Throws std::runtime_error when the device cannot
// be used.
std::unique_ptr<BatchFundamentalEstimator> CreateGpuFundamentalEstimator(const TwoViewGeometryOptions& options,
                                                                         int gpu_index);

}  // namespace cuda
}  // namespace cashash
