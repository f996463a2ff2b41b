// Which BatchVerifier a run uses: the GPU one on the run's first device
// (ResolvedRun::gpu_index, chosen by ChooseRunDevices), else the CPU thread
// pool.
#pragma once

#include <memory>

#include "cashash/pipeline/batch_verifier.h"
#include "cashash/matching/guided_matching.h"
#include "colmap_bridge/api/command_options.h"

namespace cashash {
namespace colmap {

// The verifier on device `gpu_index`, -1: the CPU.
std::unique_ptr<BatchVerifier> CreateBatchVerifierOnDevice(const MatcherCommandOptions& options, int gpu_index);

// The F estimator of guided matching's stage 1, on the same device.
std::unique_ptr<BatchFundamentalEstimator> CreateFundamentalEstimatorOnDevice(const MatcherCommandOptions& options,
                                                                              int gpu_index);

}  // namespace colmap
}  // namespace cashash
