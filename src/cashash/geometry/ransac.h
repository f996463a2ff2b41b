// LO-RANSAC with COLMAP's stopping rule, over small estimator classes.
//
// An estimator provides:
//   using Model = ...;
//   static constexpr int kSampleSize;     // minimal sample
//   static constexpr int kMaxModels;      // most models one solve returns
//   static constexpr int kMinLocalSize;   // fewest inliers for a local refit
//   size_t NumData() const;
//   int MinimalSolve(const int* sample, Model* models) const;
//   int LocalSolve(const std::vector<int>& inliers, Model* models) const;
//   RansacSupport Score(const Model&, double max_residual, int must_reach) const;
//   bool RejectedBySprt(const Model&, double max_residual, const SprtTest&,
//                       int start, int step) const;  // SprtRejectsResiduals
//   void Inliers(const Model&, double max_residual, std::vector<int>*) const;
//   void InlierMask(const Model&, double max_residual, std::vector<char>*) const;
// where residuals are squared errors compared against max_residual
// (= max_error^2), and Score may give up (returning num_inliers = -1) once the
// model cannot reach `must_reach` inliers any more.
#pragma once

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#if defined(__AVX2__)
#include <immintrin.h>
#endif

#include "cashash/geometry/random_sampler.h"
#include "cashash/geometry/ransac_early_exit.h"
#include "cashash/geometry/ransac_sprt.h"

namespace cashash {

struct RansacOptions {
  double max_error = 4.0;
  double confidence = 0.999;
  int min_num_trials = 100;
  int max_num_trials = 10000;
  // A priori lowest inlier ratio: caps the trials at the count needed for it.
  double min_inlier_ratio = 0.25;
  // COLMAP multiplies the textbook trial count by 3 to be safe.
  double num_trials_multiplier = 3.0;
  uint64_t seed = 0;
  // Stop pairs whose supports look like chance (ransac_early_exit.h); off
  // while early_exit.min_num_inliers is 0.
  RansacEarlyExitOptions early_exit;
  // When > 0: stop once the best model has fewer inliers than this and a
  // model with this many would, with `confidence`, have been found by now
  // (COLMAP's own trial rule for that inlier count). For H, whose count
  // only matters to the decision above a fraction of F's (two-view
  // geometry); 0 keeps COLMAP's loop.
  int relevant_inliers = 0;
  // When > 0: stop (after min_num_trials) once the best model has this many
  // inliers, from which more inliers cannot change the decision, only which
  // inliers it keeps (E against F's and H's counts, two-view geometry;
  // EssentialSettledInliers). 0 keeps COLMAP's loop.
  int settled_inliers = 0;
  // Reject wrong hypotheses by the sequential test before scoring them
  // (ransac_sprt.h) at this risk per model; 0 scores every one in full.
  float sprt_max_risk = 0;
};

struct RansacSupport {
  int num_inliers = 0;
  double residual_sum = std::numeric_limits<double>::max();

  // More inliers win; ties go to the smaller residual sum (COLMAP's
  // InlierSupportMeasurer).
  bool BetterThan(const RansacSupport& other) const {
    return num_inliers > other.num_inliers ||
           (num_inliers == other.num_inliers && residual_sum < other.residual_sum);
  }
};

template <typename Model>
struct RansacReport {
  bool success = false;
  int num_trials = 0;
  bool early_exit = false;  // stopped before the cap by a rule COLMAP's loop lacks
  RansacSupport support;
  Model model = Model::Zero();
  std::vector<char> inlier_mask;
};

// Trials needed to draw one all-inlier sample of `sample_size` with the given
// confidence, times `multiplier`; saturates at INT_MAX.
inline int RansacRequiredTrials(size_t num_inliers, size_t num_samples, double confidence,
                                double multiplier, int sample_size) {
  const double inlier_ratio = static_cast<double>(num_inliers) / static_cast<double>(num_samples);
  const double nom = 1.0 - confidence;
  if (nom <= 0) return INT_MAX;
  const double denom = 1.0 - std::pow(inlier_ratio, sample_size);
  if (denom <= 0) return 1;
  if (denom == 1.0) return INT_MAX;
  const double trials = std::ceil(std::log(nom) / std::log(denom) * multiplier);
  return trials >= static_cast<double>(INT_MAX) ? INT_MAX : static_cast<int>(trials);
}

// The hard cap on trials: max_num_trials, lowered to what min_inlier_ratio
// would require (COLMAP evaluates this with 100000 hypothetical samples).
inline int RansacMaxTrials(const RansacOptions& options, int sample_size) {
  constexpr size_t kNumSamples = 100000;
  const int from_ratio = RansacRequiredTrials(
      static_cast<size_t>(options.min_inlier_ratio * kNumSamples), kNumSamples,
      options.confidence, options.num_trials_multiplier, sample_size);
  return std::min(options.max_num_trials, from_ratio);
}

// One function because the trial loop, the local optimisation and the four
// stopping rules (adaptive, relevant_inliers, settled_inliers, early exit)
// read and update the same best support, model and trial counters, in COLMAP's order.
template <typename Estimator>
RansacReport<typename Estimator::Model> LoRansac(const Estimator& estimator,
                                                 const RansacOptions& options) {
  using Model = typename Estimator::Model;
  constexpr int kSampleSize = Estimator::kSampleSize;
  constexpr int kMaxLocalIterations = 10;

  RansacReport<Model> report;
  const size_t num_data = estimator.NumData();
  if (num_data < static_cast<size_t>(kSampleSize)) return report;

  const double max_residual = options.max_error * options.max_error;
  const int max_trials = RansacMaxTrials(options, kSampleSize);
  int dyn_max_trials = max_trials;

  SplitMix64 rng(options.seed);
  std::array<int, kSampleSize> sample;
  std::array<Model, Estimator::kMaxModels> models;
  std::array<Model, Estimator::kMaxModels> local_models;
  std::vector<int> inliers;
  inliers.reserve(num_data);

  RansacSupport best;
  Model best_model = Model::Zero();
  bool have_model = false;
  int trials = 0;
  bool done = false;
  // Supports of the early-exit window, scored in full (no give-up).
  const RansacEarlyExitOptions& early = options.early_exit;
  double window_support_sum = 0, window_hypotheses = 0, hypotheses = 0;
  const int relevant_trials =
      options.relevant_inliers > 0
          ? std::max(options.min_num_trials,
                     RansacRequiredTrials(static_cast<size_t>(options.relevant_inliers), num_data, options.confidence,
                                          options.num_trials_multiplier, kSampleSize))
          : INT_MAX;
  // The sequential test's own stream, so that the samples are those of a run
  // without it.
  constexpr uint64_t kSprtStreamTag = 0x5350525455ull;  // "SPRTU"
  SplitMix64 sprt_rng(DeriveSeed(options.seed, kSprtStreamTag));
  const int sprt_step = SprtOrderStep(static_cast<int>(num_data));
  for (; trials < max_trials && !done; ++trials) {
    SampleDistinct(rng, static_cast<uint32_t>(num_data), kSampleSize, sample.data());
    const int num_models = estimator.MinimalSolve(sample.data(), models.data());
    // The window's supports fit the chance model; once a model has
    // min_num_inliers the early exit cannot fire, so they are no longer read.
    const bool in_window =
        early.min_num_inliers > 0 && trials < early.window && best.num_inliers < early.min_num_inliers;
    hypotheses += num_models;
    for (int m = 0; m < num_models; ++m) {
      const int must_reach = in_window ? 0 : best.num_inliers;
      const SprtTest sprt = MakeSprtTest(must_reach, static_cast<int>(num_data), options.sprt_max_risk);
      // A model the test rejects counts as one that gave up in the scan.
      const bool rejected =
          sprt.active && estimator.RejectedBySprt(models[m], max_residual, sprt,
                                                  static_cast<int>(sprt_rng.Below(static_cast<uint32_t>(num_data))),
                                                  sprt_step);
      RansacSupport support;
      support.num_inliers = -1;
      if (!rejected) support = estimator.Score(models[m], max_residual, must_reach);
      if (in_window) {
        window_support_sum += support.num_inliers;
        window_hypotheses += 1;
      }
      if (support.BetterThan(best)) {
        best = support;
        best_model = models[m];
        have_model = true;
        // Local optimisation: refit on the inliers while the set grows.
        if (best.num_inliers > kSampleSize && best.num_inliers >= Estimator::kMinLocalSize) {
          for (int it = 0; it < kMaxLocalIterations; ++it) {
            estimator.Inliers(best_model, max_residual, &inliers);
            const int num_local = estimator.LocalSolve(inliers, local_models.data());
            const int previous = best.num_inliers;
            for (int l = 0; l < num_local; ++l) {
              const RansacSupport local =
                  estimator.Score(local_models[l], max_residual, best.num_inliers);
              if (local.BetterThan(best)) {
                best = local;
                best_model = local_models[l];
              }
            }
            if (best.num_inliers <= previous) break;
          }
        }
        dyn_max_trials = RansacRequiredTrials(best.num_inliers, num_data, options.confidence,
                                              options.num_trials_multiplier, kSampleSize);
      }
      if (trials >= dyn_max_trials && trials >= options.min_num_trials) {
        done = true;
        break;
      }
    }
    if (!done && best.num_inliers < options.relevant_inliers && trials + 1 >= relevant_trials) {
      done = true;
      report.early_exit = true;
    }
    if (!done && options.settled_inliers > 0 && best.num_inliers >= options.settled_inliers &&
        trials + 1 >= options.min_num_trials) {
      done = true;
      report.early_exit = true;
    }
    if (!done && RansacEarlyExitCheckpoint(early, trials + 1) &&
        RansacShouldExitEarly(early, static_cast<int>(num_data), kSampleSize, window_support_sum,
                              window_hypotheses, best.num_inliers, hypotheses, trials + 1,
                              max_trials - (trials + 1))) {
      done = true;
      report.early_exit = true;
    }
  }

  report.num_trials = trials;
  report.support = best;
  report.model = best_model;
  if (!have_model || best.num_inliers < kSampleSize) return report;
  report.success = true;
  estimator.InlierMask(best_model, max_residual, &report.inlier_mask);
  return report;
}

// Shared scoring loop: `residual(i)` gives the squared error (float) of pair i. Works
// in blocks: residuals are first written to a small buffer (a pure map the
// compiler vectorises; a floating-point sum would otherwise pin the loop to
// scalar order), then counted and summed in four SIMD lanes. Between blocks it
// gives up once `must_reach` inliers are out of reach.
template <typename ResidualFn>
inline RansacSupport ScoreResiduals(size_t n, double max_residual, int must_reach,
                                    ResidualFn residual) {
  constexpr size_t kBlock = 256;
  alignas(64) float r[kBlock];
  const float threshold_f = static_cast<float>(max_residual);
  RansacSupport support;
  int count = 0;
  double sum = 0;
  for (size_t begin = 0; begin < n; begin += kBlock) {
    const size_t len = std::min(kBlock, n - begin);
    for (size_t i = 0; i < len; ++i) r[i] = residual(begin + i);
    int block_count = 0;
    double block_sum = 0;
    size_t i = 0;
#if defined(__AVX2__)
    // Compare-and-mask in eight lanes: the mask selects 1 for the count and
    // the residual itself for the sum (NaN residuals compare false). Counts
    // stay exact in float: a lane sees at most kBlock / 8 pairs.
    const __m256 threshold = _mm256_set1_ps(threshold_f);
    const __m256 one = _mm256_set1_ps(1.0f);
    __m256 lane_count = _mm256_setzero_ps(), lane_sum = _mm256_setzero_ps();
    for (; i + 8 <= len; i += 8) {
      const __m256 v = _mm256_load_ps(r + i);
      const __m256 in = _mm256_cmp_ps(v, threshold, _CMP_LE_OQ);
      lane_count = _mm256_add_ps(lane_count, _mm256_and_ps(in, one));
      lane_sum = _mm256_add_ps(lane_sum, _mm256_and_ps(in, v));
    }
    alignas(32) float counts[8], sums[8];
    _mm256_store_ps(counts, lane_count);
    _mm256_store_ps(sums, lane_sum);
    for (int l = 0; l < 8; ++l) {
      block_count += static_cast<int>(counts[l]);
      block_sum += sums[l];
    }
#endif
    for (; i < len; ++i) {
      const bool in = r[i] <= threshold_f;
      block_count += in;
      block_sum += in ? r[i] : 0.0;
    }
    count += block_count;
    sum += block_sum;
    const size_t remaining = n - begin - len;
    if (static_cast<size_t>(count) + remaining < static_cast<size_t>(must_reach)) {
      support.num_inliers = -1;
      return support;
    }
  }
  support.num_inliers = count;
  support.residual_sum = sum;
  return support;
}

// The sequential test (ransac_sprt.h) on `residual(i)`, compared in float as
// ScoreResiduals compares (a NaN counts as an outlier).
template <typename ResidualFn>
inline bool SprtRejectsResiduals(size_t n, double max_residual, const SprtTest& t, int start, int step,
                                 ResidualFn residual) {
  const float threshold = static_cast<float>(max_residual);
  return SprtRejects(t, static_cast<int>(n), start, step,
                     [&](int i) { return residual(static_cast<size_t>(i)) <= threshold; });
}

template <typename ResidualFn>
inline void CollectInliers(size_t n, double max_residual, ResidualFn residual,
                           std::vector<int>* inliers) {
  // Same float comparison as ScoreResiduals, so counts and sets agree.
  const float threshold = static_cast<float>(max_residual);
  inliers->clear();
  for (size_t i = 0; i < n; ++i) {
    if (residual(i) <= threshold) inliers->push_back(static_cast<int>(i));
  }
}

template <typename ResidualFn>
inline void CollectInlierMask(size_t n, double max_residual, ResidualFn residual,
                              std::vector<char>* mask) {
  const float threshold = static_cast<float>(max_residual);
  mask->assign(n, 0);
  for (size_t i = 0; i < n; ++i) (*mask)[i] = residual(i) <= threshold;
}

}  // namespace cashash
