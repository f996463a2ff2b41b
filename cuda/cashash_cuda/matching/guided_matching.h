// GPU parts of Ga-CasHash (cashash/guided_matching.h): the stage-1 F
// estimation by the batched GPU RANSAC. Stage 2 is the GPU cascade matcher's
// Match with epipolar guides (CreateGpuFeatureMatcher).
#pragma once

#include <memory>

#include "cashash/matching/guided_matching.h"
#include "cashash_cuda/utils/gpu_resources.h"

namespace cashash {
namespace cuda {

// F of every pair of a batch in one launch (GpuTwoViewRansac; its H
// estimates are dropped). Throws std::runtime_error when the device cannot
// be used. Its buffers come from `resources` (null: an owner of its own).
std::unique_ptr<BatchFundamentalEstimator> CreateGpuFundamentalEstimator(
    const TwoViewGeometryOptions& options, int gpu_index, std::shared_ptr<GpuResources> resources = nullptr);

}  // namespace cuda
}  // namespace cashash
