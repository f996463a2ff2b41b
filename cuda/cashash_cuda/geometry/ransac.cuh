// Launch interface of the batched LO-RANSAC kernels (plain structs, so the
// host side can be ordinary C++): one thread block per pair, each thread one
// hypothesis per round, the block scoring the local refits together.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "cashash/geometry/ransac_early_exit.h"

namespace cashash {
namespace cuda {

// One pair's correspondences: points[offset, offset + count) as
// (x1, y1, x2, y2) in the pair's normalised coordinates.
struct RansacPairInput {
  int offset = 0;
  int count = 0;
  float squared_threshold = 0;  // compared against float residuals, as on the CPU
  int reference = -1;           // E: the pair's slot in RansacLaunch::reference_F / _H; -1 none
  uint64_t seed = 0;            // DeriveSeed(pair seed, model tag)
};

struct RansacPairOutput {
  double model[9];              // row-major, unit norm, normalised coordinates
  int success;
  int num_inliers;
  int num_trials;
  int num_local_refits;
  int early_exit;  // 1 when a rule COLMAP's loop lacks stopped the pair (chance, or no effect on the decision)
};

struct RansacLaunch {
  const float4* points = nullptr;
  const RansacPairInput* pairs = nullptr;
  RansacPairOutput* outputs = nullptr;
  uint8_t* masks = nullptr;     // one byte per correspondence, same offsets as points
  int num_pairs = 0;
  int max_trials = 0;           // RansacMaxTrials of the CPU path
  int min_trials = 0;
  double confidence = 0.999;
  double trials_multiplier = 3.0;
  int shared_points = 0;        // pairs with at most this many points are cached in shared memory
  RansacEarlyExitOptions early_exit;  // the CPU path's chance test; off when min_num_inliers is 0
  // The sequential test's risk per model (ransac_sprt.h); 0 scores every
  // hypothesis in full.
  float sprt_max_risk = 0;
  // H after F (TwoViewRelevantHomographyInliers): F's outputs of the same
  // pairs, read by the H blocks to stop once no H that could change the
  // decision exists; nullptr keeps COLMAP's loop.
  const RansacPairOutput* relevance = nullptr;
  double relevance_ratio = 0;
  int relevance_min_inliers = 0;
  // E after F and H (TwoViewEssentialSettledInliers): their outputs, read
  // at each E pair's `reference` slot, so that E stops once it can no longer
  // change the decision (EssentialSettledInliers); nullptr keeps COLMAP's
  // loop.
  const RansacPairOutput* reference_F = nullptr;
  const RansacPairOutput* reference_H = nullptr;
  double reference_E_F_ratio = 0;    // min_E_F_inlier_ratio
  double reference_max_H_ratio = 0;  // max_H_inlier_ratio
  int reference_min_inliers = 0;     // max(min_num_inliers, E's sample size)
};

// Threads per block (trials per round) of the F/H kernel and of the E
// kernel. E blocks of 256, not 128: a pair needing thousands of trials takes
// half the rounds, and such pairs set a chunk's device time (H200: 0.96 s of
// device time against 1.48 s with 128 at 300 images).
constexpr int kRansacThreads = 128;
constexpr int kEssentialLargeBlockThreads = 256;

// Largest shared-memory point cache an F/H launch may ask for (48 KiB of
// float4; three F/H blocks share an SM).
constexpr int kRansacMaxSharedPoints = 3072;
// The same for E launches: 160 KiB, since an E block of 256 holds an SM
// alone anyway (255 registers). The scan of each model over the pair's
// points is most of an E block's time (ncu), so the large pairs' points
// come from shared memory too: verification's device time on a 300-image
// street 0.98 s against 1.04 s from global memory.
constexpr int kEssentialMaxSharedPoints = 10240;

// F of F.num_pairs pairs and H of H.num_pairs pairs in one grid (F blocks
// first; callers put the largest pairs first so the tail is short). With
// H.relevance set, H needs F's outputs: call it twice on one stream, F
// alone (H.num_pairs 0), then H alone (F.num_pairs 0).
void LaunchTwoViewRansac(const RansacLaunch& F, const RansacLaunch& H, cudaStream_t stream);

// E (5-point LO-RANSAC on normalised camera coordinates) of E.num_pairs
// pairs, in a kernel of its own (the 5-point solver needs far more registers
// and stack than F and H).
void LaunchEssentialRansac(const RansacLaunch& E, cudaStream_t stream);

// Tests and benchmarks: the device 5-point solver on num_samples samples of 5
// correspondences (x1, y1, x2, y2 floats, 20 per sample); up to 10 row-major
// models (90 doubles) and their count per sample. Synchronous; returns the
// kernel's milliseconds (transfers excluded), one thread per sample, 128 per
// block as in the RANSAC kernel.
float EssentialFivePointOnDevice(const float* samples, int num_samples, double* models, int* counts);

// Tests: E's local-refit basis (the four null-space vectors of
// five_point::LeastSquaresNullSpace, 36 doubles per matrix) of num_matrices
// normal matrices (45 upper-triangle doubles each), computed as the RANSAC
// kernel computes it, the eigen decomposition by a warp. Synchronous.
void EssentialLocalBasisOnDevice(const double* uppers, int num_matrices, double* bases);

// Tests: the 5-point solve of E's local refit on num_bases bases (36 doubles
// each, as EssentialLocalBasisOnDevice gives them), by a warp as the RANSAC
// kernel runs it (WarpSolveFromBasis) and by one device thread
// (five_point::SolveFromBasis): up to 10 row-major models (90 doubles) and
// their count per basis, for each. Synchronous; models past a count are 0.
void EssentialSolveFromBasisOnDevice(const double* bases, int num_bases, double* warp_models, int* warp_counts,
                                     double* thread_models, int* thread_counts);

}  // namespace cuda
}  // namespace cashash
