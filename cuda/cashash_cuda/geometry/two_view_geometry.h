// Geometric verification on the GPU: F (7-point LO-RANSAC, Sampson error),
// H (4-point LO-RANSAC, transfer error) and, for calibrated pairs, E
// (5-point LO-RANSAC on normalised camera coordinates) of many pairs at
// once, one thread block per pair and model. The configuration decision and
// the watermark test stay on the CPU and are the CPU path's own code
// (DecideTwoViewGeometry), so both paths decide alike.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "cashash/pipeline/batch_verifier.h"
#include "cashash/geometry/two_view_geometry.h"
#include "cashash_cuda/utils/gpu_resources.h"

namespace cashash {
namespace cuda {

// Accumulated over Estimate calls.
struct GpuRansacStats {
  size_t pairs = 0;
  size_t points = 0;
  double seconds_total = 0;  // Estimate calls, wall time
  double seconds_gpu = 0;    // upload, kernels and download (CUDA events)
  long long trials_F = 0, trials_H = 0;
  long long local_refits_F = 0, local_refits_H = 0;
  size_t pairs_E = 0;  // pairs whose E was estimated on the device
  long long trials_E = 0, local_refits_E = 0;
  // Model estimations stopped by the chance test (ransac_early_exit.h).
  long long early_exits_F = 0, early_exits_H = 0, early_exits_E = 0;
};

// F and H estimation for batches of pairs on one device. Not thread-safe:
// one Estimate call at a time.
class GpuTwoViewRansac {
 public:
  // Throws std::runtime_error when the device cannot be used. Its buffers
  // come from `resources` (null: an owner of its own without a budget);
  // Estimate throws DeviceMemoryError, before anything is queued, when
  // they have no room.
  GpuTwoViewRansac(const TwoViewGeometryOptions& options, int gpu_index,
                   std::shared_ptr<GpuResources> resources = nullptr);
  ~GpuTwoViewRansac();
  GpuTwoViewRansac(const GpuTwoViewRansac&) = delete;
  GpuTwoViewRansac& operator=(const GpuTwoViewRansac&) = delete;

  // F and H of every pair, in the form EstimateFundamental and
  // EstimateHomography give them (pixel models of unit norm, inlier masks
  // per match). Pair k's RANSAC is seeded from seeds[k] as the CPU path
  // seeds it (DeriveSeed(seed, kSeedF / kSeedH)); the sample sequence
  // differs from the CPU's, but the same seed gives the same result.
  // `while_running`, when set, runs on the calling thread while the kernels
  // run (the batch verifier estimates E there).
  void Estimate(const std::vector<const TwoViewPoints*>& pairs, const std::vector<uint64_t>& seeds,
                std::vector<TwoViewModelEstimate>* F, std::vector<TwoViewModelEstimate>* H,
                const std::function<void()>& while_running = {});

  // The same, and E of every pair k with essential[k] != nullptr (its points
  // and threshold from PrepareEssentialPoints), in the form EstimateEssential
  // gives it (model in normalised camera coordinates, unit norm, seeded by
  // DeriveSeed(seeds[k], kSeedE)); (*E)[k] stays unset (no success) for the
  // other pairs. `essential` is empty or has one entry per pair. E runs in a
  // kernel of its own, concurrently with F and H.
  void Estimate(const std::vector<const TwoViewPoints*>& pairs, const std::vector<uint64_t>& seeds,
                const std::vector<const EssentialPoints*>& essential, std::vector<TwoViewModelEstimate>* F,
                std::vector<TwoViewModelEstimate>* H, std::vector<TwoViewModelEstimate>* E,
                const std::function<void()>& while_running = {});

  const GpuRansacStats& stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Chunks the GPU verifier keeps on the device at once (its
// MaxConcurrentCalls), by default. More chunks at once help where
// verification sets the pace and cost a little where matching does, since
// their E blocks hold SMs the matching kernels want; 2 takes most of the
// first and little of the second. The pipeline's second verification
// thread takes a chunk only on a backlog or after matching (the
// verification stage in matching_pipeline.cc), which keeps the gain without
// the cost. docs/gpu_verification.md has the figures.
constexpr int kDefaultGpuVerificationsInFlight = 2;
constexpr int kMaxGpuVerificationsInFlight = 8;

// What the GPU verifier is set up with, given to its constructor.
struct GpuVerifierConfig {
  int gpu_index = 0;
  // CPU threads that prepare the points and decide (-1: all cores).
  int num_threads = -1;
  // Chunks verified on the device at once, 1 to kMaxGpuVerificationsInFlight
  // (values outside are clamped).
  int verifications_in_flight = kDefaultGpuVerificationsInFlight;
  // The owner of the device's memory, shared with the run's matchers (null:
  // one of its own without a budget).
  std::shared_ptr<GpuResources> resources;
};

// The BatchVerifier that estimates F, H and E of a whole chunk on the GPU
// and prepares points and decides on CPU threads. A chunk whose buffers
// find no room on the device (DeviceMemoryError) is verified on the CPU
// instead; StatsSummary counts those chunks.
std::unique_ptr<BatchVerifier> CreateGpuBatchVerifier(const TwoViewGeometryOptions& options,
                                                      const GpuVerifierConfig& config);
// The same with the default number of verifications in flight.
std::unique_ptr<BatchVerifier> CreateGpuBatchVerifier(const TwoViewGeometryOptions& options, int gpu_index,
                                                      int num_threads);


}  // namespace cuda
}  // namespace cashash
