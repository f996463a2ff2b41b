// Early exit of RANSAC for pairs whose matches look like chance.
//
// Why: a pair that does not overlap still gets a few dozen matches by chance.
// COLMAP's stopping rule only shortens a run once a good model is found, so
// such a pair runs E, F and H to the trial cap (10,000 trials each) and is
// then declared degenerate. On a large collection most pairs are of this
// kind and they set the verification time.
//
// The test: after a window of trials scored in full, the supports of the
// hypotheses seen so far describe what chance gives on this pair. Each
// hypothesis' support is modelled as sample_size + X with X ~ Binomial(n -
// sample_size, delta) (every other match lies within the threshold of a
// random model with probability delta). delta is fitted twice and the larger
// value kept:
//   - from the mean support of the window, plus three standard errors;
//   - from the best support so far (local refits included): the delta for
//     which that best is the 1-in-K event of K hypotheses. Matches cluster,
//     so supports are more spread than a binomial; calibrating on the
//     observed extreme keeps the tail honest.
// The run stops when, under that model, the hypotheses left up to the trial
// cap reach min_num_inliers with probability at most max_risk. Then the
// decision (fewer than min_num_inliers inliers) is the one the full run
// would reach unless the rest of the run finds a model that chance does not
// explain, which the window's best did not show. Tested against the full
// budget on real pairs (tests/geometry/ransac_early_exit_test.cc) and measured in
// docs/gpu_verification.md.
//
// Written once for the CPU (ransac.h) and the GPU (ransac.cu), so
// that both stop after the same trial for the same supports.
#pragma once

#include <cmath>

#include "cashash/base/host_device.h"

namespace cashash {

struct RansacEarlyExitOptions {
  // Fewest inliers that make a model count (TwoViewGeometry.min_num_inliers);
  // 0 disables the exit.
  int min_num_inliers = 0;
  // Largest probability, under the chance model, that the trials left would
  // have reached min_num_inliers.
  double max_risk = 0.001;
  // Trials scored in full before the first test; later tests at 2x, 4x, ...
  int window = 256;
};

// P(X >= k) for X ~ Binomial(n, p). Returns 1 once k is at or below the mean
// (callers only need small tails).
CASHASH_HOST_DEVICE inline double BinomialUpperTail(int n, double p, int k) {
  if (k <= 0) return 1.0;
  if (k > n || p <= 0.0) return 0.0;
  if (p >= 1.0 || static_cast<double>(k) <= n * p) return 1.0;
  // Terms decrease from x = k on (k is above the mode), geometrically fast.
  double log_term = lgamma(n + 1.0) - lgamma(k + 1.0) - lgamma(n - k + 1.0) + k * log(p) +
                    (n - k) * log1p(-p);
  double term = exp(log_term);
  double sum = 0.0;
  const double odds = p / (1.0 - p);
  for (int x = k; x <= n && term > 1e-300; ++x) {
    sum += term;
    if (term < 1e-17 * sum) break;
    term *= odds * static_cast<double>(n - x) / static_cast<double>(x + 1);
  }
  return sum > 1.0 ? 1.0 : sum;
}

// The delta for which P(X >= extra) = 1 / num_hypotheses (bisection; the
// tail grows with delta).
CASHASH_HOST_DEVICE inline double DeltaFromBestSupport(int num_free, int extra, double num_hypotheses) {
  if (extra <= 0 || num_free <= 0) return 0.0;
  const double target = 1.0 / (num_hypotheses > 1.0 ? num_hypotheses : 1.0);
  double lo = 0.0, hi = static_cast<double>(extra) / num_free;
  for (int it = 0; it < 50; ++it) {
    const double mid = 0.5 * (lo + hi);
    if (BinomialUpperTail(num_free, mid, extra) < target) lo = mid;
    else hi = mid;
  }
  return hi;
}

// Whether to stop now. num_data: matches of the pair; sample_size: minimal
// sample; window_support_sum / window_hypotheses: supports of the window's
// hypotheses scored in full; best_support: best so far (refits included);
// hypotheses_so_far and trials_so_far: all of them; trials_left: up to the
// cap.
CASHASH_HOST_DEVICE inline bool RansacShouldExitEarly(const RansacEarlyExitOptions& options, int num_data,
                                                      int sample_size, double window_support_sum,
                                                      double window_hypotheses, int best_support,
                                                      double hypotheses_so_far, int trials_so_far,
                                                      int trials_left) {
  if (options.min_num_inliers <= 0 || best_support >= options.min_num_inliers) return false;
  if (trials_left <= 0 || window_hypotheses <= 0 || trials_so_far <= 0) return false;
  const int num_free = num_data - sample_size;
  const int needed = options.min_num_inliers - sample_size;
  if (num_free < needed) return true;  // not enough matches left to ever reach it
  double mean_extra = window_support_sum / window_hypotheses - sample_size;
  if (mean_extra < 0) mean_extra = 0;
  double delta = mean_extra / num_free;
  delta += 3.0 * sqrt(delta * (1.0 - delta) / (window_hypotheses * num_free)) + 1.0 / (window_hypotheses * num_free);
  const double from_best = DeltaFromBestSupport(num_free, best_support - sample_size, hypotheses_so_far);
  if (from_best > delta) delta = from_best;
  const double hypotheses_left = hypotheses_so_far / trials_so_far * trials_left;
  const double tail = BinomialUpperTail(num_free, delta, needed);
  if (tail >= 1.0) return false;
  // P(at least one of the hypotheses left reaches the threshold).
  const double risk = -expm1(hypotheses_left * log1p(-tail));
  return risk <= options.max_risk;
}

// Fewest inliers a model needs to matter to the decision when only counts
// above `ratio` x max(reference, min_inliers) do (H against F's count,
// two_view_geometry.h); at least 1.
CASHASH_HOST_DEVICE inline int RelevantInliers(double ratio, int reference, int min_inliers) {
  const int base = reference > min_inliers ? reference : min_inliers;
  const int relevant = static_cast<int>(ceil(ratio * (base > 0 ? base : 0)));
  return relevant > 1 ? relevant : 1;
}

// Fewest E inliers from which the decision is CALIBRATED whatever E finds
// later (two_view_geometry.h), given F's and H's inlier counts (0 where that
// model failed): more than e_f_ratio x F's (any count when F failed, as
// COLMAP's division by zero gives), at least min_inliers, and H / E at most
// max_h_ratio. E's count only grows during a run, so from there on more
// trials change which inliers are kept, not the decision. 0 when no count
// up to num_matches settles it. One function for the CPU and the GPU.
CASHASH_HOST_DEVICE inline int EssentialSettledInliers(double e_f_ratio, double max_h_ratio, int min_inliers,
                                                       int num_F, int num_H, int num_matches) {
  // Truncated lower bounds (each at or below where its test starts to
  // pass), then the tests exactly as the decision writes them.
  int count = min_inliers > 1 ? min_inliers : 1;
  const int from_F = static_cast<int>(e_f_ratio * num_F);
  // A ratio of 0 admits no H inlier at all: then only num_H == 0 settles.
  const int from_H = max_h_ratio > 0 ? static_cast<int>(num_H / max_h_ratio) : (num_H > 0 ? num_matches + 1 : 0);
  if (from_F > count) count = from_F;
  if (from_H > count) count = from_H;
  for (; count <= num_matches; ++count) {
    const bool above_F = num_F <= 0 || static_cast<double>(count) / num_F > e_f_ratio;
    const bool H_below = !(static_cast<double>(num_H) / count > max_h_ratio);
    if (above_F && H_below) return count;
  }
  return 0;
}

// Trial counts at which the test runs: the window, then each doubling.
CASHASH_HOST_DEVICE inline bool RansacEarlyExitCheckpoint(const RansacEarlyExitOptions& options, int trials) {
  if (options.min_num_inliers <= 0 || options.window <= 0 || trials < options.window) return false;
  int checkpoint = options.window;
  while (checkpoint < trials) checkpoint *= 2;
  return checkpoint == trials;
}

}  // namespace cashash
