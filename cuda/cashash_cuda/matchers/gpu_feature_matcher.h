// The GPU matching backend: Cascade Hashing and exact brute force on CUDA,
// behind the same interfaces as the CPU backends (MatchingBackend:
// FeatureMatcher and ExactMatcher).
#pragma once

#include <memory>
#include <string>

#include "cashash/matchers/exact_matcher.h"
#include "cashash_cuda/matchers/gpu_matcher_config.h"

namespace cashash {
namespace cuda {

// Number of usable CUDA devices (0 when there is no driver or no device).
int NumCudaDevices();

// True if device gpu_index can be used; otherwise *reason says why.
bool CudaDeviceUsable(int gpu_index, std::string* reason);

// Throws std::runtime_error when the device cannot be used, and
// std::invalid_argument for options with a value still chosen for the run
// (matcher auto, tau 0, rematch threshold -1: CasHashOptions::CheckDecided;
// a run decides them first, ResolveRun).
std::unique_ptr<MatchingBackend> CreateGpuFeatureMatcher(const SiftMatchingOptions& sift_options,
                                                         const CasHashOptions& cashash_options,
                                                         const MeanDescriptor& mean, const GpuMatcherConfig& config);

// The same on device gpu_index, with no memory cap and the default kernels.
std::unique_ptr<MatchingBackend> CreateGpuFeatureMatcher(const SiftMatchingOptions& sift_options,
                                                         const CasHashOptions& cashash_options,
                                                         const MeanDescriptor& mean, int gpu_index);

}  // namespace cuda
}  // namespace cashash
