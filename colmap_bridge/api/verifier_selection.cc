#include "colmap_bridge/api/verifier_selection.h"

#ifdef CASHASH_WITH_CUDA
#include "cashash_cuda/matching/guided_matching.h"
#include "cashash_cuda/geometry/two_view_geometry.h"
#endif

namespace cashash {
namespace colmap {

std::unique_ptr<BatchVerifier> CreateBatchVerifierOnDevice(const MatcherCommandOptions& options, int gpu_index,
                                                           RunGpuResources* gpu) {
#ifdef CASHASH_WITH_CUDA
  if (gpu_index >= 0) {
    cuda::GpuVerifierConfig config;
    config.gpu_index = gpu_index;
    config.num_threads = options.sift.num_threads;
    config.verifications_in_flight = options.gpu_verifications_in_flight;
    if (gpu != nullptr) config.resources = gpu->ForDevice(gpu_index);
    return cuda::CreateGpuBatchVerifier(options.two_view, config);
  }
#else
  (void)gpu_index;
  (void)gpu;
#endif
  return CreateCpuBatchVerifier(options.two_view, options.sift.num_threads);
}

std::unique_ptr<BatchFundamentalEstimator> CreateFundamentalEstimatorOnDevice(const MatcherCommandOptions& options,
                                                                              int gpu_index, RunGpuResources* gpu) {
#ifdef CASHASH_WITH_CUDA
  if (gpu_index >= 0) {
    return cuda::CreateGpuFundamentalEstimator(options.two_view, gpu_index,
                                               gpu != nullptr ? gpu->ForDevice(gpu_index) : nullptr);
  }
#else
  (void)gpu_index;
  (void)gpu;
#endif
  return CreateCpuFundamentalEstimator(options.two_view, options.sift.num_threads);
}

}  // namespace colmap
}  // namespace cashash
