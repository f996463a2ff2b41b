// Which BatchVerifier a run uses: the GPU one when use_gpu is set, CUDA was
// built and a device is usable, else the CPU thread pool.
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "cashash/pipeline/batch_verifier.h"
#include "cashash/matching/guided_matching.h"
#include "colmap_bridge/api/command_options.h"
#include "colmap_bridge/api/run_gpu_resources.h"

namespace cashash {
namespace colmap {

// `warning` hears why the GPU was not used when it was asked for. With
// `gpu`, the GPU verifier takes its memory from its device's owner there.
std::unique_ptr<BatchVerifier> CreateBatchVerifierForOptions(const MatcherCommandOptions& options,
                                                             const std::function<void(const std::string&)>& warning,
                                                             RunGpuResources* gpu = nullptr);

// The F estimator of guided matching's stage 1, chosen the same way.
std::unique_ptr<BatchFundamentalEstimator> CreateFundamentalEstimatorForOptions(const MatcherCommandOptions& options,
                                                                                RunGpuResources* gpu = nullptr);

}  // namespace colmap
}  // namespace cashash
