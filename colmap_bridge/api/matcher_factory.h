// Which devices a run uses and which FeatureMatcher it builds from its
// options: CreateMatcherForOptions and ResolveOptionsForRun (declared in
// matching_api.h, the public API) are defined beside these helpers.
#pragma once

#include <string>
#include <vector>

#include "colmap_bridge/api/command_options.h"

namespace cashash {
namespace colmap {

// The devices of --FeatureMatching.gpu_index: "-1" (the first), "2", or a
// comma-separated list "0,1" (one matcher per device, SplitFeatureMatcher).
// Throws std::invalid_argument for anything else.
std::vector<int> GpuIndices(const std::string& gpu_index);

// The device the matcher will run on, or -1 for the CPU.
int GpuIndexForRun(const MatcherCommandOptions& options);

}  // namespace colmap
}  // namespace cashash
