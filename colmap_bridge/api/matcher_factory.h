// Which device a run uses and which FeatureMatcher it builds from its
// options: CreateMatcherForOptions and ResolveOptionsForRun (declared in
// matching_api.h, the public API) are defined beside these helpers.
#pragma once

#include <future>

#include "colmap_bridge/api/command_options.h"

namespace cashash {
namespace colmap {

// The device the matcher will run on, or -1 for the CPU.
int GpuIndexForRun(const MatcherCommandOptions& options);

// Starts the run's GPU (its CUDA context) on a thread of its own, so that
// it overlaps opening the database and reading the feature counts; a CUDA
// call on another thread meanwhile waits for it. Errors are left to the
// run's own first use of the device, which reports them. Nothing is started
// without use_gpu, or with CASHASH_GPU_START=serial (to compare).
std::future<void> StartGpuInBackground(const MatcherCommandOptions& options);

}  // namespace colmap
}  // namespace cashash
