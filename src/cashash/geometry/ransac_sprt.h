// Sequential rejection of RANSAC hypotheses: Wald's sequential probability
// ratio test, as R-RANSAC with SPRT uses it (Chum and Matas, "Optimal
// Randomized RANSAC", 2008).
//
// Why: once a good model is known, almost every later hypothesis is wrong,
// yet each is scored over the pair's matches until even all the matches left
// could not beat the best (`must_reach`). With 37 % inliers that is still two
// thirds of the matches for every wrong model, and scoring was most of E's
// device time (ncu). A wrong model shows itself after a few dozen matches.
//
// The test. Only a model with more than `must_reach` inliers can change the
// run, i.e. one whose inlier rate is above eps = must_reach / n. Before the
// scan, the model's residuals are read in a spread order (SprtOrderStep) from a
// random start; after each match the log of the likelihood ratio of "rate
// delta" against "rate eps" grows by log((1 - delta) / (1 - eps)) for an
// outlier and by log(delta / eps) for an inlier, and the model is rejected
// once it passes log(1 / max_risk). For a model whose rate is eps or more that
// ratio is a non-negative supermartingale of mean at most 1 (reading the
// spread order as random draws), so by Ville's inequality it ever reaches
// 1 / max_risk with probability at most max_risk, whatever delta is: a model
// that would have beaten the best is lost with probability at most max_risk.
// A model that survives the test is scored in full, in match order, exactly
// as without it; so every support that is kept is the one the scan gives.
//
// delta (eps / 2) only sets which models go and how fast: the drift is
// positive, so a model is rejected sooner or later, below about 0.72 eps;
// with eps = 0.37 a model of rate 0.05 goes after about 30 matches. The
// test runs only where that is much shorter than the scan it saves.
//
// Measured: 3-11 % off GPU verification on 300-image streets, every
// decision unchanged. Less than hoped: most of E's time is in
// pairs of low inlier ratio that run to the trial cap, where the test is off
// (docs/gpu_verification.md).
//
// Written once for the host (ransac.h) and the device
// (cuda/cashash_cuda/geometry/ransac.cu).
#pragma once

#include <cmath>

#include "cashash/base/host_device.h"

namespace cashash {

// Most matches the test reads before it hands a model to the full scan.
constexpr int kSprtMaxMatches = 256;

struct SprtTest {
  bool active = false;
  float log_inlier = 0;   // log(delta / eps) < 0
  float log_outlier = 0;  // log((1 - delta) / (1 - eps)) > 0
  float log_reject = 0;   // log(1 / max_risk)
  int max_matches = 0;    // matches read at most
};

// The test for a model that must have more than `must_reach` of `n` inliers
// to count; inactive when max_risk is not in (0, 1), or where a model
// without a single inlier would need more than half the matches it may read
// to be rejected (the test would cost about what it saves).
CASHASH_HOST_DEVICE inline SprtTest MakeSprtTest(int must_reach, int n, float max_risk) {
  SprtTest t;
  if (!(max_risk > 0.f && max_risk < 1.f) || must_reach <= 0 || n <= 0 || must_reach >= n) return t;
  const float eps = static_cast<float>(must_reach) / static_cast<float>(n);
  const float delta = 0.5f * eps;
  t.log_inlier = logf(delta / eps);
  t.log_outlier = logf((1.f - delta) / (1.f - eps));
  t.log_reject = -logf(max_risk);
  t.max_matches = n / 2 < kSprtMaxMatches ? n / 2 : kSprtMaxMatches;
  t.active = t.log_reject < 0.5f * static_cast<float>(t.max_matches) * t.log_outlier;
  return t;
}

// The step of the spread order over n matches: about n / golden ratio, and
// coprime with n, so that start, start + step, ... (mod n) visits every match
// once and neighbours in match order (often neighbours in the image) land
// far apart.
CASHASH_HOST_DEVICE inline int SprtOrderStep(int n) {
  if (n <= 2) return 1;
  int step = static_cast<int>(0.6180339887 * n);
  if (step < 1) step = 1;
  for (;; ++step) {
    int a = n, b = step;
    while (b != 0) {
      const int r = a % b;
      a = b;
      b = r;
    }
    if (a == 1) return step;
  }
}

// Whether the test rejects the model whose inlier test for match i is
// `is_inlier(i)`: matches start, start + step, ... (mod n), at most
// t.max_matches of them. Callers check t.active first. The matches are
// tested `Group` at a time (up to Group - 1 past the last one the test
// needs): the tests of a group do not depend on each other, so a GPU thread
// keeps them in flight together instead of one dependent chain per match;
// the ratio grows in the same order and stops at the same match, so the
// decision is the same for every Group.
template <int Group = 1, typename IsInlier>
CASHASH_HOST_DEVICE inline bool SprtRejects(const SprtTest& t, int n, int start, int step, IsInlier is_inlier) {
  float log_ratio = 0.f;
  int i = start;
  for (int k = 0; k < t.max_matches; k += Group) {
    bool inlier[Group];
#if defined(__CUDA_ARCH__)
#pragma unroll
#endif
    for (int g = 0; g < Group; ++g) {
      inlier[g] = is_inlier(i);
      i += step;
      if (i >= n) i -= n;
    }
    for (int g = 0; g < Group && k + g < t.max_matches; ++g) {
      log_ratio += inlier[g] ? t.log_inlier : t.log_outlier;
      if (log_ratio > t.log_reject) return true;
    }
  }
  return false;
}

}  // namespace cashash
