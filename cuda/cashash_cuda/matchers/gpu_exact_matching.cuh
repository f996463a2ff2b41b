// The GPU cascade's exact matching (ExactMatcher, exact_matcher.h): brute
// force from the descriptors the cascade keeps on the device, never
// uploaded again. Now, on the cascade's stream, or held for later: a held
// exact matcher keeps the pairs' blocks of device memory (and the owner they
// return to) and runs on any thread with brute-force kernels of its own, on
// a stream of their own, while the cascade goes on. One job: exact matches
// from device descriptors. Internal to the GPU cascade matcher.
#pragma once

#include <cuda_runtime.h>

#include <memory>
#include <vector>

#include "cashash/base/object_pool.h"
#include "cashash/matchers/exact_matcher.h"
#include "cashash_cuda/matchers/gpu_cascade_image_store.cuh"
#include "cashash_cuda/matching/brute_force_matcher.cuh"

namespace cashash {
namespace cuda {

// Brute-force kernels with a stream of their own, for held exact matchers
// that run on other threads; a pool keeps one per thread that runs one.
class ExactKernels {
 public:
  ExactKernels(int device, std::shared_ptr<GpuResources> resources);
  // Also runs for kernels that failed half-way, which are not given back:
  // their stream may hold half a batch and goes with them.
  ~ExactKernels();
  ExactKernels(const ExactKernels&) = delete;
  ExactKernels& operator=(const ExactKernels&) = delete;

  BruteForceKernels* kernels() { return kernels_.get(); }
  size_t scratch_bytes() const { return resources_->ScratchBytes(); }

 private:
  const int device_;
  std::shared_ptr<GpuResources> resources_;  // outlives kernels_
  cudaStream_t stream_ = nullptr;
  std::unique_ptr<BruteForceKernels> kernels_;
};
using ExactKernelsPool = ObjectPool<ExactKernels>;

class GpuExactMatching {
 public:
  // Matches on `stream` (idle between the cascade's calls) with scratch
  // from `resources`; `device` is the cascade's.
  GpuExactMatching(int device, std::shared_ptr<GpuResources> resources, cudaStream_t stream,
                   const MatchThresholds& thresholds);
  GpuExactMatching(const GpuExactMatching&) = delete;
  GpuExactMatching& operator=(const GpuExactMatching&) = delete;

  // Exact matches of the pairs of `store`'s images, now.
  std::vector<FeatureMatches> Match(const GpuCascadeImageStore& store, const std::vector<ImagePair>& pairs);
  // An exact matcher of the pairs that holds their images' blocks (no
  // second upload, beside the next chunk's images, and no early free).
  std::unique_ptr<ExactMatcher> Hold(const GpuCascadeImageStore& store, const std::vector<ImagePair>& pairs);

 private:
  const int device_;
  std::shared_ptr<GpuResources> resources_;
  cudaStream_t stream_;
  const MatchThresholds thresholds_;
  std::unique_ptr<BruteForceKernels> kernels_;     // Match's, made on first use
  std::shared_ptr<ExactKernelsPool> held_kernels_;  // the held matchers', made on first use
};

}  // namespace cuda
}  // namespace cashash
