// `cashash geometric_verifier`: verifies the matches already stored in a
// COLMAP database (COLMAP 4's geometric_verifier) and writes
// two_view_geometries, on the GPU when one is usable.
#pragma once

#include <string>

#include "colmap_bridge/api/command_options.h"
#include "colmap_bridge/api/matching_api.h"

namespace cashash {
namespace colmap {

// Verifies every pair of table matches that has no two_view_geometries row
// yet (every pair with options.overwrite). Matching options are ignored.
// Throws as MatchExhaustive does.
MatchingSummary VerifyExistingMatches(const std::string& database_path, const MatcherCommandOptions& options,
                                      const MatchingCallbacks& callbacks = {});

// The command line: returns the process exit code.
int RunGeometricVerifier(int argc, const char* const* argv);

}  // namespace colmap
}  // namespace cashash
