// Batched LO-RANSAC for F, H and E. Per pair (one block), per round: every
// thread draws its own sample from a stream keyed by (pair seed, trial
// index), solves it and scores its models over all correspondences (the
// hypotheses in parallel); then the block walks the round's trials in trial
// order exactly as the CPU loop walks its trials: a trial that beats the
// best so far (more inliers, then a smaller residual sum) becomes the best
// and the block refits it on its inliers (8-point or DLT, the CPU path's
// local optimisation; 5-point least-squares refits for E, which may give
// several models, each scored) while the inlier set grows. COLMAP's adaptive
// stopping rule is evaluated after each round. Every decision depends on
// the trial order only, never on timing, so a seed gives one result.
#include "cashash_cuda/geometry/ransac.cuh"

#include <algorithm>
#include <cfloat>
#include <map>
#include <mutex>
#include <utility>

#include "cashash/geometry/five_point_solver.h"
#include "cashash/geometry/ransac_sprt.h"
#include "cashash_cuda/geometry/essential_matrix.cuh"
#include "cashash_cuda/geometry/fundamental_matrix.cuh"
#include "cashash_cuda/geometry/homography_matrix.cuh"
#include "cashash_cuda/utils/cuda_check.cuh"

namespace cashash {
namespace cuda {
namespace {

using namespace ransac;  // NOLINT: the solvers of this kernel

constexpr int kMaxLocalIterations = 10;
constexpr int kMaxLocalModels = five_point::kMaxSolutions;  // models of one local refit

// Orders supports: more inliers first, then the smaller residual sum
// (non-negative floats order as their bit patterns). 0 = no model.
__device__ inline unsigned long long SupportKey(int count, float sum) {
  return (static_cast<unsigned long long>(count) << 32) |
         (0xFFFFFFFFull - static_cast<unsigned long long>(__float_as_uint(sum)));
}

template <int Threads>
struct BlockScratch {
  static constexpr int kWarps = Threads / 32;
  unsigned long long keys[Threads];  // each trial's best support this round
  double models[Threads][9];         // and its model
  int warp_count[kWarps];
  double warp_sum[kWarps];
  double warp_upper[kWarps][45];
  double upper[45];
  double best_model[9];
  double local_models[kMaxLocalModels][9];
  // E's local refit by warp 0 (EssentialModel::WarpLocalSolve): the normal
  // matrix's eigen decomposition, then the 5-point solver on its basis.
  double jacobi_a[81];
  double jacobi_v[81];
  WarpFivePointScratch refit_solver;
  unsigned long long best_key;
  int best_count;
  int num_local;
  int num_local_refits;
  // Early exit (ransac_early_exit.h): supports of the window's hypotheses,
  // hypotheses so far, and the decision.
  double window_support_sum;
  int window_hypotheses;
  int hypotheses;
  int exit_early;
};

// Inlier count and residual sum of one model over the pair, by the block.
template <typename Model, int Threads>
__device__ void BlockScore(const float* m, const float4* points, int n, float threshold, BlockScratch<Threads>& s,
                           int* count, float* sum) {
  int c = 0;
  float r_sum = 0;
  for (int i = threadIdx.x; i < n; i += Threads) {
    const float r = Model::Residual(m, points[i]);
    if (r <= threshold) {
      ++c;
      r_sum += r;
    }
  }
  double d_sum = r_sum;
  for (int offset = 16; offset > 0; offset >>= 1) {
    c += __shfl_down_sync(0xffffffffu, c, offset);
    d_sum += __shfl_down_sync(0xffffffffu, d_sum, offset);
  }
  const int warp = threadIdx.x / 32, lane = threadIdx.x % 32;
  if (lane == 0) {
    s.warp_count[warp] = c;
    s.warp_sum[warp] = d_sum;
  }
  __syncthreads();
  int total = 0;
  double total_sum = 0;
  for (int w = 0; w < BlockScratch<Threads>::kWarps; ++w) {
    total += s.warp_count[w];
    total_sum += s.warp_sum[w];
  }
  __syncthreads();  // the scratch may be reused at once
  *count = total;
  *sum = static_cast<float>(total_sum);
}

// Least-squares refit of the best model on its inliers: the block sums the
// normal matrix, thread 0 solves it (s.num_local models in s.local_models).
template <typename Model, int Threads>
__device__ void BlockLocalSolve(const float* best, const float4* points, int n, float threshold,
                                BlockScratch<Threads>& s) {
  double upper[45];
  for (int k = 0; k < 45; ++k) upper[k] = 0;
  for (int i = threadIdx.x; i < n; i += Threads) {
    const float4 p = points[i];
    if (Model::Residual(best, p) <= threshold) Model::AddRows(p, upper);
  }
  const int warp = threadIdx.x / 32, lane = threadIdx.x % 32;
  for (int k = 0; k < 45; ++k) {
    double v = upper[k];
    for (int offset = 16; offset > 0; offset >>= 1) v += __shfl_down_sync(0xffffffffu, v, offset);
    if (lane == 0) s.warp_upper[warp][k] = v;
  }
  __syncthreads();
  if (threadIdx.x < 45) {
    double v = 0;
    for (int w = 0; w < BlockScratch<Threads>::kWarps; ++w) v += s.warp_upper[w][threadIdx.x];
    s.upper[threadIdx.x] = v;
  }
  __syncthreads();
  if constexpr (Model::kWarpLocalSolve) {
    // E: warp 0 refits. On thread 0 alone its eigen decomposition and its
    // roots kept the block's other warps waiting here.
    if (threadIdx.x < 32) {
      const int num = Model::WarpLocalSolve(s.upper, s.jacobi_a, s.jacobi_v, s.refit_solver, s.local_models);
      if (threadIdx.x == 0) {
        s.num_local = num;
        ++s.num_local_refits;
      }
    }
  } else if (threadIdx.x == 0) {
    s.num_local = Model::LocalSolve(s.upper, s.best_model, s.local_models);
    ++s.num_local_refits;
  }
  __syncthreads();
}

// The inlier test of one match for a model, by one thread: whether its
// residual (num2 / den for a Sampson model) is at most the threshold. A
// Sampson model decides without dividing wherever a margin of 2^-16
// relative settles it (far above the float product's rounding, and t * den
// stays a normal float for den >= 1e-30), and divides only inside that
// band, or for den < 1e-30 or a NaN: the same decision as the division for
// every match.
// The margin, relative to the threshold, on either side.
constexpr float kMarginBelow = 1.0f - 1.0f / 65536.0f;  // accept = threshold * kMarginBelow
constexpr float kMarginAbove = 1.0f + 1.0f / 65536.0f;  // reject = threshold * kMarginAbove

struct SampsonDecision {
  bool decided;  // by the margin
  bool inlier;   // when decided
};

__device__ __forceinline__ SampsonDecision DecideByMargin(float num2, float den, float accept, float reject) {
  const bool normal = den >= 1e-30f;
  const bool sure_in = normal && num2 <= accept * den;
  const bool sure_out = normal && num2 > reject * den;
  return {sure_in || sure_out, sure_in};
}

template <typename Model>
__device__ __forceinline__ bool IsInlier(const float* f, float4 p, float threshold, float accept, float reject) {
  if constexpr (Model::kSampsonResidual) {
    float num2, den;
    SampsonParts(f, p, &num2, &den);
    const SampsonDecision d = DecideByMargin(num2, den, accept, reject);
    return d.decided ? d.inlier : num2 / den <= threshold;  // rare: the band, a tiny den, a NaN
  } else {
    return Model::Residual(f, p) <= threshold;
  }
}

// Inliers among points[i, i + kCountGroup) of a Sampson model: the loads
// first, then every residual, with one branch for the whole group (taken
// only when a match falls in the margin's band). ncu put 73 % of the E
// kernel's stall samples in the scan, one point after another,
// each ending in a branch (the division of an inlier, which the warp's
// other lanes waited for); so a thread ran one dependent chain at a time
// at 2 warps per scheduler. Here it has kCountGroup independent chains.
// Measured (every decision the same): the division out alone gained
// nothing, the groups E 2-12 % at 8,192 features and 3 % at 16,384; ncu
// then put the scan at 24 % and the barrier after the trials at 52 %: the
// round waits for its slowest warp (docs/gpu_verification.md).
constexpr int kCountGroup = 8;

template <typename Model>
__device__ __forceinline__ int CountSampsonGroup(const float* f, const float4* __restrict__ points, float threshold,
                                                 float accept, float reject) {
  float4 p[kCountGroup];
#pragma unroll
  for (int k = 0; k < kCountGroup; ++k) p[k] = points[k];
  float num2[kCountGroup], den[kCountGroup];
  bool decided[kCountGroup];
  int count = 0;
  bool all_decided = true;
#pragma unroll
  for (int k = 0; k < kCountGroup; ++k) {
    SampsonParts(f, p[k], &num2[k], &den[k]);
    const SampsonDecision d = DecideByMargin(num2[k], den[k], accept, reject);
    decided[k] = d.decided;
    count += d.inlier ? 1 : 0;
    all_decided = all_decided && d.decided;
  }
  if (!all_decided) {
#pragma unroll
    for (int k = 0; k < kCountGroup; ++k) {
      if (!decided[k] && num2[k] / den[k] <= threshold) ++count;
    }
  }
  return count;
}

// Inliers of one model over the pair by one thread, in point order; false
// once `must_reach` is out of reach (checked after every 64 points). No
// residual is summed here: only a model that has its trial's most inliers
// and at least the round's best needs its sum (RunTrial), and summing meant
// the division above for every inlier. The caller passes the points where
// they are (shared memory when cached), so that the loads need not go
// through generic addressing.
template <typename Model>
__device__ __forceinline__ bool CountInliers(const float* f, const float4* __restrict__ points, int n, float threshold,
                                             int must_reach, int* count_out) {
  const float accept = threshold * kMarginBelow;
  const float reject = threshold * kMarginAbove;
  int count = 0;
  for (int base = 0; base < n; base += 64) {
    const int end = min(n, base + 64);
    int i = base;
    if constexpr (Model::kSampsonResidual) {
      for (; i + kCountGroup <= end; i += kCountGroup) {
        count += CountSampsonGroup<Model>(f, points + i, threshold, accept, reject);
      }
    }
    for (; i < end; ++i) count += IsInlier<Model>(f, points[i], threshold, accept, reject) ? 1 : 0;
    // Give up once the pair's best so far is out of reach.
    if (end - base == 64 && count + (n - end) < must_reach) return false;
  }
  *count_out = count;
  return true;
}

// The residual sum of a model's inliers, in point order (the order, and so
// the float sum, that the walk's comparisons have always used). A Sampson
// model divides kCountGroup points at a time, each as before, so that the
// divisions do not wait for each other.
template <typename Model>
__device__ __forceinline__ float InlierResidualSum(const float* f, const float4* __restrict__ points, int n,
                                                   float threshold) {
  const float reject = threshold * kMarginAbove;  // skip, as DecideByMargin, what is surely outside
  float sum = 0;
  int i = 0;
  if constexpr (Model::kSampsonResidual) {
    for (; i + kCountGroup <= n; i += kCountGroup) {
      float num2[kCountGroup], den[kCountGroup], r[kCountGroup];
#pragma unroll
      for (int k = 0; k < kCountGroup; ++k) {
        SampsonParts(f, points[i + k], &num2[k], &den[k]);
        r[k] = num2[k] / den[k];
      }
#pragma unroll
      for (int k = 0; k < kCountGroup; ++k) {
        if (den[k] >= 1e-30f && num2[k] > reject * den[k]) continue;
        if (r[k] <= threshold) sum += r[k];
      }
    }
  }
  for (; i < n; ++i) {
    float r;
    if constexpr (Model::kSampsonResidual) {
      float num2, den;
      SampsonParts(f, points[i], &num2, &den);
      if (den >= 1e-30f && num2 > reject * den) continue;
      r = num2 / den;
    } else {
      r = Model::Residual(f, points[i]);
    }
    if (r <= threshold) sum += r;
  }
  return sum;
}

// Whether the sequential test (ransac_sprt.h) rejects the model before its
// scan: matches start, start + step, ..., kCountGroup at a time (a Sampson
// model compares num2 with threshold * den, without dividing; a NaN counts
// as an outlier).
template <typename Model>
__device__ __forceinline__ bool SprtRejectsModel(const SprtTest& t, const float* f,
                                                 const float4* __restrict__ points, int n, float threshold,
                                                 int start, int step) {
  return SprtRejects<kCountGroup>(t, n, start, step, [&](int i) {
    if constexpr (Model::kSampsonResidual) {
      float num2, den;
      SampsonParts(f, points[i], &num2, &den);
      return num2 <= threshold * den;
    } else {
      return Model::Residual(f, points[i]) <= threshold;
    }
  });
}

// One trial on one thread: the sample drawn from the trial's stream, its
// models solved, and each tested (the sequential test) and counted; the
// trial's best support (key 0: none) and that model's index in `models`,
// its hypotheses and, in the window, the sum of their supports. `points` is
// cached_points or global_points, as `cached` says (the sample's loads).
// The key orders by inliers, then by the smaller residual sum, so only the
// models with the trial's most inliers can be its best, and the sum decides
// nothing below `sum_from` (the round's best count: such a key loses to the
// best in the walk whatever its sum): sums are taken only where they can
// decide, and every key that can win is the one a full scan gave.
struct TrialOutcome {
  unsigned long long key = 0;
  int model = -1;
  int hypotheses = 0;
  int support_sum = 0;
};

template <typename Model>
__device__ __forceinline__ TrialOutcome RunTrial(uint64_t seed, int trial, const float4* points, bool cached,
                                                 const float4* cached_points, const float4* global_points, int n,
                                                 float threshold, bool in_window, int must_reach, int sum_from,
                                                 const SprtTest& sprt, int sprt_step,
                                                 double (&models)[Model::kMaxModels][9]) {
  TrialOutcome out;
  DeviceSplitMix64 rng = TrialRng(seed, static_cast<uint32_t>(trial));
  int idx[Model::kSampleSize];
  SampleDistinct<Model::kSampleSize>(rng, static_cast<uint32_t>(n), idx);
  // Drawn after the sample, so the samples are those of a run without the test.
  const int sprt_start = sprt.active ? static_cast<int>(rng.Below(static_cast<uint32_t>(n))) : 0;
  float4 sample[Model::kSampleSize];
  for (int k = 0; k < Model::kSampleSize; ++k) sample[k] = points[idx[k]];
  const int num_models = Model::Minimal(sample, models);
  out.hypotheses = num_models;
  int counts[Model::kMaxModels];
  int most = -1;
  for (int m = 0; m < num_models; ++m) {
    counts[m] = -1;
    float f[9];
    for (int k = 0; k < 9; ++k) f[k] = static_cast<float>(models[m][k]);
    // Shared and global points in separate calls: no generic addressing in the loops.
    if (sprt.active && (cached ? SprtRejectsModel<Model>(sprt, f, cached_points, n, threshold, sprt_start, sprt_step)
                            : SprtRejectsModel<Model>(sprt, f, global_points, n, threshold, sprt_start, sprt_step))) {
      continue;
    }
    int count = 0;
    const bool counted = cached ? CountInliers<Model>(f, cached_points, n, threshold, must_reach, &count)
                                : CountInliers<Model>(f, global_points, n, threshold, must_reach, &count);
    if (!counted) continue;
    if (in_window) out.support_sum += count;
    counts[m] = count;
    most = max(most, count);
  }
  if (most < 0) return out;
  for (int m = 0; m < num_models; ++m) {
    if (counts[m] != most) continue;
    float sum = 0;
    if (most >= sum_from) {
      float f[9];
      for (int k = 0; k < 9; ++k) f[k] = static_cast<float>(models[m][k]);
      sum = cached ? InlierResidualSum<Model>(f, cached_points, n, threshold)
                   : InlierResidualSum<Model>(f, global_points, n, threshold);
    }
    const unsigned long long key = SupportKey(most, sum);
    if (key > out.key) {
      out.key = key;
      out.model = m;
    }
    if (most < sum_from) break;  // no sum can decide: the first such model stands for the trial
  }
  return out;
}

// Thread 0 clears the block's running state before a pair.
template <int Threads>
__device__ __forceinline__ void ResetPairState(BlockScratch<Threads>& s) {
  if (threadIdx.x == 0) {
    s.best_key = 0;
    s.best_count = 0;
    s.num_local_refits = 0;
    s.window_support_sum = 0;
    s.window_hypotheses = 0;
    s.hypotheses = 0;
    s.exit_early = 0;
  }
}

// The output of a pair with fewer matches than a sample: no model, no trial.
__device__ __forceinline__ void WriteNoModel(RansacPairOutput* output) {
  if (threadIdx.x == 0) {
    output->success = 0;
    output->num_inliers = 0;
    output->num_trials = 0;
    output->num_local_refits = 0;
    output->early_exit = 0;
  }
}

// Where a pair's run may stop before its trial cap because no further trial
// can change the two-view decision.
struct DecisionLimits {
  // H after F: fewest inliers that can change the decision and the trials
  // after which such a model would have been found (the CPU's
  // RansacOptions::relevant_inliers); 0: no such limit.
  int relevant = 0;
  int relevant_trials = 0;
  // E after F and H: from `settled` inliers on, more trials cannot change
  // the decision (the CPU's TwoViewEssentialSettledInliers); 0: none.
  int settled = 0;
};

template <typename Model>
__device__ __forceinline__ DecisionLimits DecisionLimitsOfPair(const RansacLaunch& launch,
                                                               const RansacPairInput& input, int pair, int n) {
  DecisionLimits limits;
  limits.relevant_trials = launch.max_trials;
  if (launch.relevance != nullptr) {
    const RansacPairOutput& f = launch.relevance[pair];
    const int num_f = f.success ? f.num_inliers : 0;
    limits.relevant = RelevantInliers(launch.relevance_ratio, num_f, launch.relevance_min_inliers);
    limits.relevant_trials = max(launch.min_trials, RequiredTrials(limits.relevant, n, launch.confidence,
                                                                   launch.trials_multiplier, Model::kSampleSize));
  }
  if (launch.reference_F != nullptr && input.reference >= 0) {
    const RansacPairOutput& f = launch.reference_F[input.reference];
    const RansacPairOutput& h = launch.reference_H[input.reference];
    limits.settled = EssentialSettledInliers(launch.reference_E_F_ratio, launch.reference_max_H_ratio,
                                             launch.reference_min_inliers, f.success ? f.num_inliers : 0,
                                             h.success ? h.num_inliers : 0, n);
  }
  return limits;
}

// Publishes this thread's trial for the walk: its best key and model, and
// its hypotheses (and, in the window, its supports) for the early exit.
template <typename Model, int Threads>
__device__ __forceinline__ void PublishTrial(const TrialOutcome& mine, bool in_window,
                                             const RansacEarlyExitOptions& early,
                                             const double (&models)[Model::kMaxModels][9], BlockScratch<Threads>& s) {
  s.keys[threadIdx.x] = mine.key;
  if (early.min_num_inliers > 0) {
    if (mine.hypotheses > 0) atomicAdd(&s.hypotheses, mine.hypotheses);
    if (in_window && mine.hypotheses > 0) {
      atomicAdd(&s.window_hypotheses, mine.hypotheses);
      atomicAdd(&s.window_support_sum, static_cast<double>(mine.support_sum));
    }
  }
  if (mine.model >= 0) {
    for (int k = 0; k < 9; ++k) s.models[threadIdx.x][k] = models[mine.model][k];
  }
}

// Local optimisation of the best model, as the CPU path: refit while the
// inlier set grows, each model of a refit compared in turn.
template <typename Model, int Threads>
__device__ __forceinline__ void LocallyOptimizeBest(const float4* points, int n, float threshold,
                                                    BlockScratch<Threads>& s) {
  for (int it = 0; it < kMaxLocalIterations; ++it) {
    const int previous = s.best_count;
    float f[9];
    for (int k = 0; k < 9; ++k) f[k] = static_cast<float>(s.best_model[k]);
    BlockLocalSolve<Model, Threads>(f, points, n, threshold, s);
    // Each model of the refit in turn, as the CPU loop compares them.
    for (int l = 0; l < s.num_local; ++l) {
      float lf[9];
      for (int k = 0; k < 9; ++k) lf[k] = static_cast<float>(s.local_models[l][k]);
      int count;
      float sum;
      BlockScore<Model, Threads>(lf, points, n, threshold, s, &count, &sum);
      // Only thread 0 reads the best here (others would race with its write).
      if (threadIdx.x == 0) {
        const unsigned long long key = SupportKey(count, sum);
        if (key > s.best_key) {
          for (int k = 0; k < 9; ++k) s.best_model[k] = s.local_models[l][k];
          s.best_key = key;
          s.best_count = count;
        }
      }
    }
    __syncthreads();
    if (s.best_count <= previous) break;
  }
}

// Walks the published trials of a round in trial order as the CPU loop
// would: each trial that beats the best so far becomes the best and is
// refined at once (refining only the round's winner would refine lucky
// wide-band models that a least-squares refit cannot improve, and lose
// inliers against the CPU). Updates the adaptive trial cap.
template <typename Model, int Threads>
__device__ __forceinline__ void WalkRound(const RansacLaunch& launch, const float4* points, int n, float threshold,
                                          BlockScratch<Threads>& s, int* dyn_max_trials) {
  unsigned long long best_key = s.best_key;
  __syncthreads();  // everyone has read the best before thread 0 may change it
  for (int t = 0; t < Threads; ++t) {
    if (s.keys[t] <= best_key) continue;  // same decision in every thread
    if (threadIdx.x == 0) {
      for (int k = 0; k < 9; ++k) s.best_model[k] = s.models[t][k];
      s.best_key = s.keys[t];
      s.best_count = static_cast<int>(s.keys[t] >> 32);
    }
    __syncthreads();
    if (s.best_count > Model::kSampleSize && s.best_count >= Model::kMinLocalSize) {
      LocallyOptimizeBest<Model, Threads>(points, n, threshold, s);
    }
    *dyn_max_trials = RequiredTrials(s.best_count, n, launch.confidence, launch.trials_multiplier,
                                     Model::kSampleSize);
    best_key = s.best_key;
    __syncthreads();  // everyone has read the best before thread 0 may change it
  }
}

// COLMAP's stopping rule after `trials_done` trials (the cap, the adaptive
// cap past min_num_trials), the decision limits and the early exit; the
// last two set s.exit_early. Ends on a barrier, so every thread decides
// alike.
template <typename Model, int Threads>
__device__ __forceinline__ bool RunEndsAfterRound(const RansacLaunch& launch, const DecisionLimits& limits, int n,
                                                  int trials_done, int dyn_max_trials, BlockScratch<Threads>& s) {
  const RansacEarlyExitOptions& early = launch.early_exit;
  const bool irrelevant =
      limits.relevant > 0 && s.best_count < limits.relevant && trials_done >= limits.relevant_trials;
  const bool decided = limits.settled > 0 && s.best_count >= limits.settled && trials_done >= launch.min_trials;
  const bool stop = trials_done >= launch.max_trials ||
                    (trials_done >= dyn_max_trials && trials_done >= launch.min_trials) || irrelevant || decided;
  if ((irrelevant || decided) && threadIdx.x == 0) s.exit_early = 1;
  if (!stop && threadIdx.x == 0 && RansacEarlyExitCheckpoint(early, trials_done) &&
      RansacShouldExitEarly(early, n, Model::kSampleSize, s.window_support_sum, s.window_hypotheses,
                            s.best_count, s.hypotheses, trials_done, launch.max_trials - trials_done)) {
    s.exit_early = 1;
  }
  __syncthreads();
  return stop || s.exit_early;
}

// The best model's inlier mask and the pair's output.
template <typename Model, int Threads>
__device__ __forceinline__ void WritePairResult(const RansacLaunch& launch, const RansacPairInput& input,
                                                RansacPairOutput* output, const float4* points, int n,
                                                float threshold, int trials_done, const BlockScratch<Threads>& s) {
  const bool success = s.best_key != 0 && s.best_count >= Model::kSampleSize;
  uint8_t* mask = launch.masks + input.offset;
  float f[9];
  for (int k = 0; k < 9; ++k) f[k] = static_cast<float>(s.best_model[k]);
  for (int i = threadIdx.x; i < n; i += Threads) {
    mask[i] = success && Model::Residual(f, points[i]) <= threshold ? 1 : 0;
  }
  if (threadIdx.x == 0) {
    for (int k = 0; k < 9; ++k) output->model[k] = s.best_model[k];
    output->success = success ? 1 : 0;
    output->num_inliers = s.best_count;
    output->num_trials = trials_done;
    output->num_local_refits = s.num_local_refits;
    output->early_exit = s.exit_early;
  }
}

// One pair on one block, round by round: every thread runs a trial
// (RunTrial), the block walks them in trial order (WalkRound), then the
// stopping rule (RunEndsAfterRound). The steps are inlined helpers sharing
// the round state and block-wide __syncthreads barriers.
template <typename Model, int Threads>
__device__ void LoRansacBlock(const RansacLaunch& launch, int pair, float4* cached_points, BlockScratch<Threads>& s) {
  const RansacPairInput input = launch.pairs[pair];
  const int n = input.count;
  const float threshold = input.squared_threshold;
  const float4* global_points = launch.points + input.offset;
  const float4* points = global_points;
  const bool cached = n <= launch.shared_points;
  if (cached) {
    for (int i = threadIdx.x; i < n; i += Threads) cached_points[i] = points[i];
    points = cached_points;
  }
  ResetPairState(s);
  __syncthreads();
  RansacPairOutput* output = launch.outputs + pair;
  if (n < Model::kSampleSize) {
    WriteNoModel(output);
    return;
  }

  int dyn_max_trials = launch.max_trials;
  int trials_done = 0;
  const RansacEarlyExitOptions& early = launch.early_exit;
  const DecisionLimits limits = DecisionLimitsOfPair<Model>(launch, input, pair, n);
  const int sprt_step = SprtOrderStep(n);
  // The first round runs COLMAP's min_num_trials only where that is at most
  // half a round: a pair that its first good model settles (most verified
  // pairs need no more) stops there instead of scoring a whole round of
  // hypotheses over all its matches. Later rounds end on multiples of
  // Threads, where the early exit's window and checkpoints lie.
  const bool short_first_round = launch.min_trials > 0 && 2 * launch.min_trials <= Threads;
  int round_start = 0;
  for (int round = 0;; ++round) {
    const int round_end = round == 0 && short_first_round ? launch.min_trials : (round_start / Threads + 1) * Threads;
    const int trial = round_start + threadIdx.x;
    // Window trials are scored in full, their supports fitting the chance
    // model, but only while no model has min_num_inliers: from then on the
    // early exit cannot fire (RansacShouldExitEarly), so nothing reads them.
    const bool in_window =
        early.min_num_inliers > 0 && trial < early.window && s.best_count < early.min_num_inliers;
    const int must_reach = in_window ? 0 : s.best_count;
    const SprtTest sprt = MakeSprtTest(must_reach, n, launch.sprt_max_risk);
    double models[Model::kMaxModels][9];
    TrialOutcome mine;
    if (trial < round_end && trial < launch.max_trials) {
      mine = RunTrial<Model>(input.seed, trial, points, cached, cached_points, global_points, n, threshold, in_window,
                             must_reach, s.best_count, sprt, sprt_step, models);
    }
    PublishTrial<Model, Threads>(mine, in_window, early, models, s);
    __syncthreads();
    WalkRound<Model, Threads>(launch, points, n, threshold, s, &dyn_max_trials);
    trials_done = min(round_end, launch.max_trials);
    round_start = round_end;
    if (RunEndsAfterRound<Model, Threads>(launch, limits, n, trials_done, dyn_max_trials, s)) break;
  }
  WritePairResult<Model, Threads>(launch, input, output, points, n, threshold, trials_done, s);
}

// F blocks first, then H blocks, in one grid: no tail between two launches.
__global__ void __launch_bounds__(kRansacThreads) TwoViewRansacKernel(RansacLaunch F, RansacLaunch H) {
  extern __shared__ float4 cached_points[];
  __shared__ BlockScratch<kRansacThreads> s;
  const int block = static_cast<int>(blockIdx.x);
  if (block < F.num_pairs) {
    LoRansacBlock<FundamentalModel, kRansacThreads>(F, block, cached_points, s);
  } else {
    LoRansacBlock<HomographyModel, kRansacThreads>(H, block - F.num_pairs, cached_points, s);
  }
}

// E blocks: a kernel of their own, so the 5-point solver's registers and
// stack do not weigh on the F/H kernel's occupancy. It takes 255 registers,
// so an SM holds 256 of its threads either way: two blocks of 128 or one of
// 256. The larger block runs twice the trials per round, so a pair that
// needs thousands of trials takes half as many rounds: those pairs are what
// a chunk waits for once the others are done.
template <int Threads>
__global__ void __launch_bounds__(Threads) EssentialRansacKernel(RansacLaunch E) {
  extern __shared__ float4 cached_points[];
  __shared__ BlockScratch<Threads> s;
  LoRansacBlock<EssentialModel, Threads>(E, static_cast<int>(blockIdx.x), cached_points, s);
}

// The point cache (float4s) `kernel` may take on the current device beside
// its static shared memory, at most max_points; raises the kernel's dynamic
// shared-memory limit to it once per device. A block may opt in to 64 KiB
// on 7.5, 99 KiB on 8.6 and 8.9, 163 KiB on 8.0 and 227 KiB on 9.0, so the
// caches the kernels were sized for on 9.0 shrink on older cards: pairs
// past the cap read their points from global memory (the same points, so
// the same results).
int SharedPointsOnDevice(const void* kernel, int max_points) {
  static std::mutex mutex;
  static std::map<std::pair<int, const void*>, int> points_of;  // (device, kernel)
  int device = 0;
  CUDA_CHECK(cudaGetDevice(&device));
  std::lock_guard<std::mutex> lock(mutex);
  const auto known = points_of.find({device, kernel});
  if (known != points_of.end()) return known->second;
  int opt_in_bytes = 0;
  CUDA_CHECK(cudaDeviceGetAttribute(&opt_in_bytes, cudaDevAttrMaxSharedMemoryPerBlockOptin, device));
  cudaFuncAttributes attributes{};
  CUDA_CHECK(cudaFuncGetAttributes(&attributes, kernel));
  const int free_bytes = std::max(0, opt_in_bytes - static_cast<int>(attributes.sharedSizeBytes));
  const int points = std::min(max_points, free_bytes / static_cast<int>(sizeof(float4)));
  CUDA_CHECK(cudaFuncSetAttribute(kernel, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                  static_cast<int>(points * sizeof(float4))));
  points_of[{device, kernel}] = points;
  return points;
}

template <int Threads>
void LaunchEssentialKernel(const RansacLaunch& E, cudaStream_t stream) {
  RansacLaunch launch = E;
  launch.shared_points = std::min(
      E.shared_points,
      SharedPointsOnDevice(reinterpret_cast<const void*>(&EssentialRansacKernel<Threads>), kEssentialMaxSharedPoints));
  const size_t shared_bytes = static_cast<size_t>(launch.shared_points) * sizeof(float4);
  EssentialRansacKernel<Threads><<<launch.num_pairs, Threads, shared_bytes, stream>>>(launch);
  CUDA_CHECK_LAUNCH();
}

// One thread per 5-point sample (tests).
__global__ void EssentialFivePointKernel(const float4* samples, int num_samples, double* models, int* counts) {
  const int i = static_cast<int>(blockIdx.x * blockDim.x + threadIdx.x);
  if (i >= num_samples) return;
  double out[five_point::kMaxSolutions][9];
  const int n = EssentialModel::Minimal(samples + 5 * i, out);
  counts[i] = n;
  for (int m = 0; m < n; ++m)
    for (int k = 0; k < 9; ++k) models[(i * five_point::kMaxSolutions + m) * 9 + k] = out[m][k];
}

// One warp per normal matrix: E's local-refit basis as the kernel finds it
// (tests).
__global__ void EssentialLocalBasisKernel(const double* uppers, int num_matrices, double* bases) {
  __shared__ double a[81], v[81];
  const int m = static_cast<int>(blockIdx.x);
  if (m >= num_matrices) return;
  double basis[4][9];
  const bool finite = EssentialModel::WarpLocalBasis(uppers + 45 * m, a, v, basis);
  if (threadIdx.x == 0) {
    for (int e = 0; e < 4; ++e)
      for (int i = 0; i < 9; ++i) bases[36 * m + 9 * e + i] = finite ? basis[e][i] : 0.0;
  }
}

// One warp per basis: the refit's 5-point solve by the warp, and by lane 0
// alone as the minimal samples run it (tests).
__global__ void EssentialSolveFromBasisKernel(const double* bases, int num_bases, double* warp_models,
                                              int* warp_counts, double* thread_models, int* thread_counts) {
  __shared__ WarpFivePointScratch scratch;
  __shared__ double models[five_point::kMaxSolutions][9];
  const int b = static_cast<int>(blockIdx.x);
  if (b >= num_bases) return;
  double basis[4][9];
  for (int e = 0; e < 4; ++e)
    for (int i = 0; i < 9; ++i) basis[e][i] = bases[36 * b + 9 * e + i];
  if (threadIdx.x == 0) {
    for (int e = 0; e < 4; ++e)
      for (int i = 0; i < 9; ++i) scratch.basis[e][i] = basis[e][i];
  }
  const int num = WarpSolveFromBasis(scratch, models);
  if (threadIdx.x == 0) {
    warp_counts[b] = num;
    for (int m = 0; m < num; ++m)
      for (int k = 0; k < 9; ++k) warp_models[(b * five_point::kMaxSolutions + m) * 9 + k] = models[m][k];
    double own[five_point::kMaxSolutions][9];
    const int own_num = five_point::SolveFromBasis(basis, own);
    thread_counts[b] = own_num;
    for (int m = 0; m < own_num; ++m)
      for (int k = 0; k < 9; ++k) thread_models[(b * five_point::kMaxSolutions + m) * 9 + k] = own[m][k];
  }
}

}  // namespace

void EssentialLocalBasisOnDevice(const double* uppers, int num_matrices, double* bases) {
  if (num_matrices <= 0) return;
  double *d_uppers = nullptr, *d_bases = nullptr;
  CUDA_CHECK(cudaMalloc(&d_uppers, sizeof(double) * 45 * num_matrices));
  CUDA_CHECK(cudaMalloc(&d_bases, sizeof(double) * 36 * num_matrices));
  CUDA_CHECK(cudaMemcpy(d_uppers, uppers, sizeof(double) * 45 * num_matrices, cudaMemcpyHostToDevice));
  EssentialLocalBasisKernel<<<num_matrices, 32>>>(d_uppers, num_matrices, d_bases);
  CUDA_CHECK_LAUNCH();
  CUDA_CHECK(cudaMemcpy(bases, d_bases, sizeof(double) * 36 * num_matrices, cudaMemcpyDeviceToHost));
  cudaFree(d_uppers);
  cudaFree(d_bases);
}

void EssentialSolveFromBasisOnDevice(const double* bases, int num_bases, double* warp_models, int* warp_counts,
                                     double* thread_models, int* thread_counts) {
  if (num_bases <= 0) return;
  const size_t model_doubles = static_cast<size_t>(num_bases) * five_point::kMaxSolutions * 9;
  double *d_bases = nullptr, *d_warp = nullptr, *d_thread = nullptr;
  int* d_counts = nullptr;
  CUDA_CHECK(cudaMalloc(&d_bases, sizeof(double) * 36 * num_bases));
  CUDA_CHECK(cudaMalloc(&d_warp, sizeof(double) * model_doubles));
  CUDA_CHECK(cudaMalloc(&d_thread, sizeof(double) * model_doubles));
  CUDA_CHECK(cudaMalloc(&d_counts, sizeof(int) * 2 * num_bases));
  CUDA_CHECK(cudaMemcpy(d_bases, bases, sizeof(double) * 36 * num_bases, cudaMemcpyHostToDevice));
  CUDA_CHECK(cudaMemset(d_warp, 0, sizeof(double) * model_doubles));
  CUDA_CHECK(cudaMemset(d_thread, 0, sizeof(double) * model_doubles));
  EssentialSolveFromBasisKernel<<<num_bases, 32>>>(d_bases, num_bases, d_warp, d_counts, d_thread,
                                                   d_counts + num_bases);
  CUDA_CHECK_LAUNCH();
  CUDA_CHECK(cudaMemcpy(warp_models, d_warp, sizeof(double) * model_doubles, cudaMemcpyDeviceToHost));
  CUDA_CHECK(cudaMemcpy(thread_models, d_thread, sizeof(double) * model_doubles, cudaMemcpyDeviceToHost));
  CUDA_CHECK(cudaMemcpy(warp_counts, d_counts, sizeof(int) * num_bases, cudaMemcpyDeviceToHost));
  CUDA_CHECK(cudaMemcpy(thread_counts, d_counts + num_bases, sizeof(int) * num_bases, cudaMemcpyDeviceToHost));
  cudaFree(d_bases);
  cudaFree(d_warp);
  cudaFree(d_thread);
  cudaFree(d_counts);
}

void LaunchEssentialRansac(const RansacLaunch& E, cudaStream_t stream) {
  if (E.num_pairs == 0) return;
  LaunchEssentialKernel<kEssentialLargeBlockThreads>(E, stream);
}

float EssentialFivePointOnDevice(const float* samples, int num_samples, double* models, int* counts) {
  if (num_samples <= 0) return 0.f;
  float4* d_samples = nullptr;
  double* d_models = nullptr;
  int* d_counts = nullptr;
  const size_t model_doubles = static_cast<size_t>(num_samples) * five_point::kMaxSolutions * 9;
  CUDA_CHECK(cudaMalloc(&d_samples, sizeof(float4) * 5 * num_samples));
  CUDA_CHECK(cudaMalloc(&d_models, sizeof(double) * model_doubles));
  CUDA_CHECK(cudaMalloc(&d_counts, sizeof(int) * num_samples));
  CUDA_CHECK(cudaMemcpy(d_samples, samples, sizeof(float4) * 5 * num_samples, cudaMemcpyHostToDevice));
  CUDA_CHECK(cudaMemset(d_models, 0, sizeof(double) * model_doubles));
  cudaEvent_t start = nullptr, stop = nullptr;
  CUDA_CHECK(cudaEventCreate(&start));
  CUDA_CHECK(cudaEventCreate(&stop));
  CUDA_CHECK(cudaEventRecord(start));
  EssentialFivePointKernel<<<(num_samples + 127) / 128, 128>>>(d_samples, num_samples, d_models, d_counts);
  CUDA_CHECK_LAUNCH();
  CUDA_CHECK(cudaEventRecord(stop));
  CUDA_CHECK(cudaEventSynchronize(stop));
  float kernel_ms = 0.f;
  CUDA_CHECK(cudaEventElapsedTime(&kernel_ms, start, stop));
  cudaEventDestroy(start);
  cudaEventDestroy(stop);
  CUDA_CHECK(cudaMemcpy(models, d_models, sizeof(double) * model_doubles, cudaMemcpyDeviceToHost));
  CUDA_CHECK(cudaMemcpy(counts, d_counts, sizeof(int) * num_samples, cudaMemcpyDeviceToHost));
  cudaFree(d_samples);
  cudaFree(d_models);
  cudaFree(d_counts);
  return kernel_ms;
}

void LaunchTwoViewRansac(const RansacLaunch& F, const RansacLaunch& H, cudaStream_t stream) {
  const int blocks = F.num_pairs + H.num_pairs;
  if (blocks == 0) return;
  // The point cache plus the static scratch may pass the default 48 KiB.
  const int cap = SharedPointsOnDevice(reinterpret_cast<const void*>(&TwoViewRansacKernel), kRansacMaxSharedPoints);
  RansacLaunch f = F, h = H;
  f.shared_points = std::min(F.shared_points, cap);
  h.shared_points = std::min(H.shared_points, cap);
  const size_t shared_bytes = static_cast<size_t>(std::max(f.shared_points, h.shared_points)) * sizeof(float4);
  TwoViewRansacKernel<<<blocks, kRansacThreads, shared_bytes, stream>>>(f, h);
  CUDA_CHECK_LAUNCH();
}

}  // namespace cuda
}  // namespace cashash
