// The options of a cascade matcher that a test or a benchmark builds
// directly, without a run. CasHashOptions' defaults leave the matcher, tau
// and the exact rematch threshold to the run (ResolveRun decides them), and
// the matcher factories and the cascade's functions refuse them undecided
// (CasHashOptions::CheckDecided). This is the cascade that keeps its own
// matches, as a run decides it without a rematch.
#pragma once

#include "cashash/matching/matching_options.h"

namespace cashash {
namespace testing_support {

// matcher kCascade, tau kCascadeTauForPrecision (43), no exact rematch (0);
// tables still 0 (the factories' 8,192-feature shape), top_k and the seed
// the defaults.
inline CasHashOptions CascadeOptions() {
  CasHashOptions options;
  options.matcher = MatcherType::kCascade;
  options.tau = kCascadeTauForPrecision;
  options.exact_rematch_min_matches = 0;
  return options;
}

}  // namespace testing_support
}  // namespace cashash
