// Which BatchVerifier a run uses: the GPU one on the run's first device
// (ResolvedRun::gpu_index, chosen by ChooseRunDevices), else the CPU thread
// pool.
#pragma once

#include <memory>

#include "cashash/pipeline/batch_verifier.h"
#include "cashash/matching/guided_matching.h"
#include "colmap_bridge/api/command_options.h"
#include "colmap_bridge/api/run_gpu_resources.h"

namespace cashash {
namespace colmap {

// The verifier on device `gpu_index`, -1: the CPU. With `gpu`, the GPU
// verifier takes its memory from its device's owner there.
std::unique_ptr<BatchVerifier> CreateBatchVerifierOnDevice(const MatcherCommandOptions& options, int gpu_index,
                                                           RunGpuResources* gpu = nullptr);

// The F estimator of guided matching's stage 1, on the same device.
std::unique_ptr<BatchFundamentalEstimator> CreateFundamentalEstimatorOnDevice(const MatcherCommandOptions& options,
                                                                              int gpu_index,
                                                                              RunGpuResources* gpu = nullptr);

}  // namespace colmap
}  // namespace cashash
