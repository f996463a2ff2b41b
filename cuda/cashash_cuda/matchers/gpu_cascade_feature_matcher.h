// Factory of the GPU Cascade Hashing FeatureMatcher (used by
// CreateGpuFeatureMatcher). Plain C++ header.
#pragma once

#include <memory>

#include "cashash/matchers/exact_matcher.h"
#include "cashash_cuda/matchers/gpu_matcher_config.h"

namespace cashash {
namespace cuda {

// Throws std::invalid_argument for options the GPU path does not support or
// with a value still chosen for the run (CasHashOptions::CheckDecided), and
// std::runtime_error when the device cannot be used.
std::unique_ptr<MatchingBackend> CreateGpuCascadeMatcher(const SiftMatchingOptions& sift_options,
                                                         const CasHashOptions& cashash_options,
                                                         const MeanDescriptor& mean, const GpuMatcherConfig& config);

}  // namespace cuda
}  // namespace cashash
