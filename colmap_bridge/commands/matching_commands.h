// The cashash commands that stand in for COLMAP's: exhaustive_matcher,
// sequential_matcher, spatial_matcher and matches_importer. Each returns the
// process exit code.
#pragma once

namespace cashash {
namespace colmap {

int RunExhaustiveMatcher(int argc, const char* const* argv);
int RunMatchesImporter(int argc, const char* const* argv);
int RunSequentialMatcher(int argc, const char* const* argv);
int RunSpatialMatcher(int argc, const char* const* argv);
// exhaustive_matcher with --GuidedMatching.enabled 1 (Ga-CasHash).
int RunGuidedMatcher(int argc, const char* const* argv);

}  // namespace colmap
}  // namespace cashash
