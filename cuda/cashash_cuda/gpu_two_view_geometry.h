// Geometric verification on the GPU: F (7-point LO-RANSAC, Sampson error)
// and H (4-point LO-RANSAC, transfer error) of many pairs in one launch,
// one thread block per pair and model. E (calibrated pairs), the
// configuration decision and the watermark test stay on the CPU and are the
// CPU path's own code (DecideTwoViewGeometry), so both paths decide alike.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "cashash/batch_verifier.h"
#include "cashash/two_view_geometry.h"

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
};

// F and H estimation for batches of pairs on one device. Not thread-safe:
// one Estimate call at a time.
class GpuTwoViewRansac {
 public:
  // Throws std::runtime_error when the device cannot be used.
  GpuTwoViewRansac(const TwoViewGeometryOptions& options, int gpu_index);
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

  const GpuRansacStats& stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The BatchVerifier that estimates F and H of a whole chunk on the GPU and
// prepares points, estimates E and decides on num_threads CPU threads.
std::unique_ptr<BatchVerifier> CreateGpuBatchVerifier(const TwoViewGeometryOptions& options, int gpu_index,
                                                      int num_threads);

}  // namespace cuda
}  // namespace cashash
