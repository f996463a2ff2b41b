// Which device a run uses and which FeatureMatcher it builds from its
// options: CreateMatcherForOptions and ResolveOptionsForRun (declared in
// matching_api.h, the public API) are defined beside these helpers.
#pragma once

#include "colmap_bridge/api/command_options.h"

namespace cashash {
namespace colmap {

// The device the matcher will run on, or -1 for the CPU.
int GpuIndexForRun(const MatcherCommandOptions& options);

}  // namespace colmap
}  // namespace cashash
