// The cashash commands that stand in for COLMAP's: exhaustive_matcher,
// sequential_matcher, spatial_matcher and matches_importer. Each returns the
// process exit code.
#pragma once

#include <string>

namespace cashash {
namespace colmap {

int RunExhaustiveMatcher(int argc, const char* const* argv);
int RunMatchesImporter(int argc, const char* const* argv);
int RunSequentialMatcher(int argc, const char* const* argv);
int RunSpatialMatcher(int argc, const char* const* argv);
// exhaustive_matcher with --GuidedMatching.enabled 1 (Ga-CasHash).
int RunGuidedMatcher(int argc, const char* const* argv);
// Retrieval from the hash codes, then the retrieved pairs (retrieval_api.h);
// `command` is "retrieval_matcher" or "vocab_tree_matcher".
int RunRetrievalMatcher(const std::string& command, int argc, const char* const* argv);

}  // namespace colmap
}  // namespace cashash
