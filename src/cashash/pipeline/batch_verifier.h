// The verification stage's backend: verifies a whole chunk of pairs in one
// call, so that a GPU implementation can run every pair's RANSAC at once.
// The CPU implementation runs EstimateTwoViewGeometry per pair on a thread
// pool; any implementation must decide configurations with the shared
// DecideTwoViewGeometry so that both paths agree.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "cashash/geometry/two_view_geometry.h"
#include "cashash/base/types.h"

namespace cashash {

// One pair to verify. The pointers must stay valid during Verify.
struct VerificationPair {
  const Camera* camera1 = nullptr;
  const std::vector<Eigen::Vector2d>* points1 = nullptr;  // keypoint pixels
  const Camera* camera2 = nullptr;
  const std::vector<Eigen::Vector2d>* points2 = nullptr;
  const FeatureMatches* matches = nullptr;
  // Replaces options.random_seed for this pair (see PairRandomSeed).
  uint64_t random_seed = 0;
};

class BatchVerifier {
 public:
  virtual ~BatchVerifier() = default;
  // "cpu" or "gpu", for the run's summary.
  virtual std::string Name() const = 0;
  // Geometries of pairs[k] in the same order. Up to MaxConcurrentCalls()
  // calls at once, from different threads.
  virtual std::vector<TwoViewGeometry> Verify(const std::vector<VerificationPair>& pairs) = 0;
  // How many Verify calls may run at once. The CPU verifier already spreads
  // one chunk over every core (1); the GPU verifier keeps several chunks on
  // the device, because one chunk's device time is set by its slowest pair
  // while most of the device idles.
  virtual int MaxConcurrentCalls() const { return 1; }
  // How many matched chunks that wait together one call should take: the
  // pipeline gives a call up to this many.
  virtual size_t ChunksPerCall() const { return 1; }
  // One line on where the time went (device time, trials, early exits), for
  // the run's log; empty when there is nothing beyond the pipeline's times.
  virtual std::string StatsSummary() const { return {}; }
  // Calls verified on the CPU because the device had no room for them (a
  // GPU verifier's fallback); 0 for the CPU verifier.
  virtual size_t CallsWithoutDeviceMemory() const { return 0; }
};

// EstimateTwoViewGeometry per pair on num_threads threads (-1 = all cores).
std::unique_ptr<BatchVerifier> CreateCpuBatchVerifier(const TwoViewGeometryOptions& options, int num_threads);

// Mixes the run's seed with the pair so that each pair's RANSAC is
// repeatable whatever else is in the run and whichever backend verifies it.
uint64_t PairRandomSeed(uint64_t base_seed, const ImagePair& pair);

// Keypoint positions in pixels, the form the verifiers read.
std::vector<Eigen::Vector2d> KeypointPositions(const Keypoints& keypoints);

}  // namespace cashash
