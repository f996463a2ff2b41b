// Options of the descriptor matching step. SiftMatchingOptions carries
// COLMAP's names and defaults so that results are comparable; CasHashOptions
// carries the Cascade Hashing parameters of our own matcher.
#pragma once

#include <cstdint>
#include <string>

namespace cashash {

struct SiftMatchingOptions {
  // Number of CPU threads; -1 uses every core (COLMAP's convention).
  int num_threads = -1;
  // Lowe's ratio test on the angle between descriptors: reject when
  // best >= max_ratio * second_best.
  double max_ratio = 0.8;
  // Reject when the best angle (radians, acos(dot / 512^2)) exceeds this.
  double max_distance = 0.7;
  // Keep mutual best matches only.
  bool cross_check = true;
  // Images with more features are truncated to the first max_num_matches
  // rows, as COLMAP does.
  int max_num_matches = 32768;

  // Returns an empty string when valid, else a message naming the option.
  std::string Check() const;
};

// kAuto is resolved from the run's data before any pair is matched
// (ChooseAutoMatcher, matcher_choice.h): never from timings, so that the
// same database and options write the same rows on every run.
enum class MatcherType { kCascade, kBruteForce, kAuto };

// CasHashOptions::tau and CasHashOptions::exact_rematch_min_matches values
// that mean "chosen for the run": ResolveRun (colmap_bridge/api/
// run_resolution.h) decides them from the run's data and options.
constexpr int kTauChosen = 0;
constexpr int kRematchMinMatchesChosen = -1;

// The defaults are the user-facing ones, one set for every user of the
// struct: the command line and Python (MatcherCommandOptions::cashash is a
// default CasHashOptions) and the library alike. Values "chosen for the run"
// (matcher auto, 0 tables, tau kTauChosen, rematch threshold
// kRematchMinMatchesChosen) depend on the run's data, device and the other
// options, so only a run can decide them: ResolveRun does, before any
// matcher is built. A matcher built from a CasHashOptions directly
// (CreateCpuFeatureMatcher, CreateGpuFeatureMatcher, the cascade's
// functions) refuses options whose matcher, tau or rematch threshold is
// still chosen (CheckDecided) rather than guess a value: the caller names
// it. (MatchImagePair without a matcher of the caller's decides them for
// the one pair it matches, pair_matching.h.) Tables left at 0 take the
// 8,192-feature shape in a matcher built directly (num_tables).
struct CasHashOptions {
  // auto | cascade | bruteforce ("--CasHash.matcher"). auto: chosen for the
  // run (MatcherRule, run_resolution.h).
  MatcherType matcher = MatcherType::kAuto;
  // Number of first-level hash tables and bits per table (bucket count is
  // 2^bits_per_table per table). What users check is how many of the exact
  // matcher's *verified* inliers survive, and that follows the raw recall
  // closely. On fountain-P11 (55 pairs, exact mutual ratio-test matches as
  // reference; docs/cascade_parameters.md): 7 x 8 keeps 93.2 %, 8 x 8 94.8 %,
  // 8 x 7 96.7 % at ~1,100 bucket entries per query and half the speed of
  // 7 x 8, 9 x 7 97.6 % at 0.8x the speed of 8 x 7. 8 x 7 is the cheapest
  // setting that keeps 95 % of the exact verified inliers; faster settings
  // are one option away (--CasHash.num_tables 7 --CasHash.bits_per_table 8).
  // The GPU backend needs num_tables * bits_per_table <= 64.
  //
  // 0 (the default) = chosen for the run (ResolveTableShape, table_shape.h)
  // from its features per image, what the cascade's matches are for
  // (TableShapeGoal: recall, or a coarser screen where the exact rematch
  // decides) and the device (TableShapeBackend: the CPU's recall shapes
  // drop the GPU's 64-bit limit from 16,384 features). A value > 0 is kept.
  // A matcher created from options still at 0 uses the 8,192-feature shape.
  int num_tables = 0;
  int bits_per_table = 0;
  // Length of the second-level remap code used for Hamming ranking. Fixed at
  // 128 bits (two 64-bit words) in every backend.
  static constexpr int kRemapBits = 128;
  // Candidates whose remap Hamming distance exceeds tau are dropped before
  // ranking (the paper's threshold), and top_k is the number of nearest
  // candidates by Hamming distance whose exact descriptor distance is
  // computed. Recall hardly depends on either (fountain-P11: 0.967 at
  // 40 / 10, 0.969 at 43 / 16), but precision does: the ratio test can only
  // reject an ambiguous match if the close second best was ranked. At
  // 40 / 10 the cascade's precision at 6 px on graf was 2.6 points below
  // exact matching (target: 2); top_k alone does not fix it (16: -2.3, 32:
  // -2.3 on hpatches v_graffiti), because the missed second bests lie just
  // beyond tau 40. 43 / 16 gives -1.8 / -1.9 points (seeds 0 to 2: at most
  // -1.9) at about 10 % more CPU matching time than 40 / 10 (within-tau
  // candidates grow about 2x per +4 of tau: 48 / 16 costs +60 %).
  // docs/cascade_parameters.md and docs/ACCURACY.md have the tables.
  // That is tau for the cascade's own matches (kCascadeTauForPrecision). When
  // the exact rematch decides every pair that may verify, the cascade only
  // screens, and a tighter tau screens as well for less
  // (kCascadeTauForScreening). Which of the two applies depends on the
  // run's rematch, so the default is kTauChosen (0): chosen for the run
  // (ChooseCascadeTau). A value > 0 is kept.
  int tau = kTauChosen;
  int top_k = 16;
  // Seed of the random projections; the same seed gives the same matches.
  uint64_t random_seed = 0;
  // Pairs whose cascade matches number at least this are matched again by
  // exact brute force, whose matches replace the cascade's
  // (exact_rematch_feature_matcher.h): the cascade screens, exact matching
  // decides the pairs that may verify. 0 = off (the cascade's matches are
  // kept). The default, kRematchMinMatchesChosen (-1), is chosen for the
  // run: 12, or 8 with the bucket screening tables (RematchMinMatchesRule,
  // run_resolution.h), since the threshold follows the run's tables and
  // device. With the cascade keeping 94 % of the exact matches (its worst
  // real set), a pair with min_num_inliers = 15 exact matches falls below
  // 12 cascade matches with probability about 1 %. Unused by brute force
  // and guided matching.
  int exact_rematch_min_matches = kRematchMinMatchesChosen;
  // When > 0, only pairs with fewer cascade matches than this are matched
  // again exactly (a window [exact_rematch_min_matches, this)): the pairs
  // near min_num_inliers, whose verification a few missed matches can
  // decide. Pairs above keep the cascade's matches, so the cascade's tables
  // and tau are then chosen for recall and precision (CascadeOnlyScreens).
  // 0 = no upper bound. The CPU's auto rule sets it (matcher_choice.h).
  int exact_rematch_max_matches = 0;

  // "" when valid, else a message naming the option. The values chosen for
  // the run are valid.
  std::string Check() const;
  // "" when nothing a matcher reads is left to the run: the matcher is
  // named (not auto), tau > 0 and the rematch threshold >= 0. Else a
  // message naming the first option still chosen. The matcher factories
  // and the cascade's functions throw std::invalid_argument with it.
  std::string CheckDecided() const;
};

// tau where the cascade's matches are kept: its precision then matters (see
// CasHashOptions::tau).
constexpr int kCascadeTauForPrecision = 43;
// tau where the exact rematch replaces the matches of every pair with at
// least exact_rematch_min_matches cascade matches: the cascade then only
// decides which pairs reach that count, and its precision does not reach
// the output. True matches lie close in remap distance; chance candidates
// near 64. At 32 the within-tau candidates per query fall 6x (sceaux_castle,
// 101 -> 16) while recall moves from 0.980 to 0.977 (sacre_coeur: 0.952 ->
// 0.943); below 32 it falls faster (30: 0.974, 28: 0.967). On the 300-image
// street the whole command ran 17 % faster with the same verified pairs and
// inlier matches (docs/cascade_parameters.md, "tau when the exact rematch
// decides").
constexpr int kCascadeTauForScreening = 32;

// Whether the cascade only screens a run's pairs: the exact rematch is on
// and the cascade's matches are not used otherwise (not kept without a
// rematch, not fed to guided matching's stage-1 model). Its tau and its
// tables (TableShapeGoal) are chosen for screening then, for precision and
// recall otherwise.
// A rematch window with an upper bound (exact_rematch_max_matches > 0)
// keeps the cascade's matches above it: the cascade does not only screen.
bool CascadeOnlyScreens(int exact_rematch_min_matches, bool guided, int exact_rematch_max_matches = 0);

// The tau a run uses when its options leave it at kTauChosen (the
// default): kCascadeTauForScreening where CascadeOnlyScreens, else
// kCascadeTauForPrecision.
int ChooseCascadeTau(int exact_rematch_min_matches, bool guided, int exact_rematch_max_matches = 0);

std::string MatcherTypeToString(MatcherType type);
// Returns false on an unknown name.
bool MatcherTypeFromString(const std::string& name, MatcherType* type);

}  // namespace cashash
