// What --CasHash.matcher auto means for a run, decided from the run's data
// (where it matches, its features per image, the options the user typed)
// before any pair is matched. Never from timings: the same database and
// options write the same `matches` and `two_view_geometries` on every run,
// whatever the load (docs/cpu_matching.md, "Reproducible by default").
//
// GPU: the cascade, with the exact rematch of every pair that may verify
// (the runs' threshold). Timed against brute force on the 300-image
// streets, the cascade forced was as fast as or faster than any timed
// choice at 2,048, 8,192 and 16,384 features (docs/BENCHMARKS.md), so the
// probe bought nothing there and made the rows depend on the clock.
//
// CPU: the cascade's own matches (tables and tau for recall and precision),
// and the exact rematch only for the pairs near the verification threshold:
// cascade match counts in [kCpuRematchWindowMin, kCpuRematchWindowMax). A
// pair below the window cannot reach min_num_inliers; a pair above it
// verifies with the cascade's matches as it would with the exact ones, and
// rematching it costs a brute-force pair (the rematch of every pair made
// the CPU default 6.6x slower than the cascade alone on castle-P30 and
// verified fewer of COLMAP's pairs). The pairs whose verification the
// rematch changes are pairs without much overlap, where the cascade's ratio
// test keeps chance matches the exact one rejects: on herzjesu-P25 (11k
// features) they had 59 and 65 cascade matches (43 and 46 exact, 16
// inliers each), and no pair with 66 or more cascade matches changed. The
// window [12, 64) catches the first (268 of COLMAP 3.8's 270 verified
// pairs, 99.3 %); [12, 96) catches both (269, as brute force) but
// rematches 65 pairs instead of 27 and made the run 1.2x slower, past the
// 15x lead over COLMAP 3.8's CPU matcher that the default is held to.
// docs/cpu_matching.md has the measurements.
//
// Options the user typed win: a rematch threshold or window given on the
// command line (or from Python) is kept on both devices.
#pragma once

#include <cstddef>
#include <string>

#include "cashash/matching/matching_options.h"

namespace cashash {

// The CPU's rematch window (cascade matches of a pair).
constexpr int kCpuRematchWindowMin = 12;
constexpr int kCpuRematchWindowMax = 64;

struct MatcherChoiceInput {
  // The run matches on a GPU (a usable device was found), else on the CPU.
  bool on_gpu = false;
  // The run's typical features per image (TypicalFeatureCount), 0 unknown.
  // Today's rule does not depend on it: on the CPU the cascade stayed
  // faster than brute force with VNNI down to 4,096 features (generated
  // street, 16 images: 2.4 against 3.4 CPU seconds), so no size switches
  // to brute force; it is here for a rule that would.
  size_t features_per_image = 0;
  // The rematch threshold and window are left to the run, not typed by the
  // user (exact_rematch_min_matches at kRematchMinMatchesChosen and
  // exact_rematch_max_matches at 0, CasHashOptions' defaults; ResolveRun
  // passes the runs' threshold in `options`).
  bool rematch_from_rule = true;
  // Guided matching needs the cascade and screens by itself.
  bool guided = false;
};

struct MatcherChoice {
  MatcherType matcher = MatcherType::kCascade;
  int exact_rematch_min_matches = 0;
  int exact_rematch_max_matches = 0;
  // One line for the run's log, e.g. "cascade, exact rematch of pairs with
  // 12 to 63 cascade matches (CPU rule)".
  std::string reason;
};

// The choice for options whose matcher is kAuto or kCascade: the cascade
// named is the cascade auto chooses, with the same rematch rule on each
// device. Brute force comes back unchanged (its rematch settings unused).
MatcherChoice ChooseAutoMatcher(const CasHashOptions& options, const MatcherChoiceInput& input);

// `options` with the choice applied (matcher, rematch threshold and window).
CasHashOptions ApplyMatcherChoice(const CasHashOptions& options, const MatcherChoice& choice);

}  // namespace cashash
