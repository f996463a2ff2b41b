// Which device a run uses and which FeatureMatcher it builds from its
// resolved options: CreateMatcherForRun (declared in matching_api.h, the
// public API) is defined beside these helpers.
#pragma once

#include <cstddef>

#include "colmap_bridge/api/command_options.h"

namespace cashash {
namespace colmap {

// The device the matcher will run on, or -1 for the CPU.
int GpuIndexForRun(const MatcherCommandOptions& options);


}  // namespace colmap
}  // namespace cashash
