// Which device a run uses and which FeatureMatcher it builds from its
// options: CreateMatcherForOptions and ResolveOptionsForRun (declared in
// matching_api.h, the public API) are defined beside these helpers.
#pragma once

#include <cstddef>

#include "colmap_bridge/api/command_options.h"

namespace cashash {
namespace colmap {

// The device the matcher will run on, or -1 for the CPU.
int GpuIndexForRun(const MatcherCommandOptions& options);

// The device memory each GPU matcher of the run may take
// (cuda::GpuMatcherConfig::memory_budget_bytes): --max_gpu_memory where
// given, else 0 (no cap but the device's own memory).
size_t GpuMatcherMemoryBudget(const MatcherCommandOptions& options);

}  // namespace colmap
}  // namespace cashash
