#include "colmap_bridge/api/verifier_selection.h"

#include <algorithm>
#include <stdexcept>

#ifdef CASHASH_WITH_CUDA
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#include "cashash_cuda/matching/guided_matching.h"
#include "cashash_cuda/geometry/two_view_geometry.h"
#endif

namespace cashash {
namespace colmap {

std::unique_ptr<BatchVerifier> CreateBatchVerifierForOptions(const MatcherCommandOptions& options,
                                                             const std::function<void(const std::string&)>& warning,
                                                             RunGpuResources* gpu) {
  if (options.use_gpu) {
#ifdef CASHASH_WITH_CUDA
    int gpu_index = 0;
    try {
      gpu_index = std::max(0, std::stoi(options.gpu_index.substr(0, options.gpu_index.find(','))));
    } catch (const std::exception&) {
      throw std::invalid_argument("--FeatureMatching.gpu_index: expected an integer or a comma-separated list, got '" +
                                  options.gpu_index + "'");
    }
    std::string reason;
    if (cuda::CudaDeviceUsable(gpu_index, &reason)) {
      cuda::GpuVerifierConfig config;
      config.gpu_index = gpu_index;
      config.num_threads = options.sift.num_threads;
      config.verifications_in_flight = options.gpu_verifications_in_flight;
      if (gpu != nullptr) config.resources = gpu->ForDevice(gpu_index);
      return cuda::CreateGpuBatchVerifier(options.two_view, config);
    }
    if (warning) warning("no usable CUDA device (" + reason + "); verifying on the CPU");
#else
    (void)gpu;
    if (warning) warning("cashash was built without CUDA; verifying on the CPU");
#endif
  }
  return CreateCpuBatchVerifier(options.two_view, options.sift.num_threads);
}

std::unique_ptr<BatchFundamentalEstimator> CreateFundamentalEstimatorForOptions(const MatcherCommandOptions& options,
                                                                                RunGpuResources* gpu) {
#ifdef CASHASH_WITH_CUDA
  if (options.use_gpu) {
    int gpu_index = 0;
    try {
      gpu_index = std::max(0, std::stoi(options.gpu_index.substr(0, options.gpu_index.find(','))));
    } catch (const std::exception&) {
      gpu_index = 0;  // CreateBatchVerifierForOptions reports the bad value
    }
    if (cuda::CudaDeviceUsable(gpu_index, nullptr)) {
      return cuda::CreateGpuFundamentalEstimator(options.two_view, gpu_index,
                                                 gpu != nullptr ? gpu->ForDevice(gpu_index) : nullptr);
    }
  }
#else
  (void)gpu;
#endif
  return CreateCpuFundamentalEstimator(options.two_view, options.sift.num_threads);
}

}  // namespace colmap
}  // namespace cashash
