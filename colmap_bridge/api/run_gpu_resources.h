// The owners of a run's GPU memory: one cuda::GpuResources per device
// (cuda/cashash_cuda/utils/gpu_resources.h), made on first use with the
// run's budget (--max_gpu_memory) and shared by everything the run puts on
// that device: the matchers, the exact rematch's tickets and pooled
// matchers, the verifier and guided matching's F estimator. Built by
// PlanRun; without CUDA it holds nothing.
#pragma once

#include <cstddef>
#include <map>
#include <memory>
#include <mutex>

namespace cashash {
namespace cuda {
class GpuResources;
}  // namespace cuda

namespace colmap {

// What the owners did over the run, summed over devices (peaks: the
// largest device's).
struct RunGpuMemoryBooks {
  size_t budget_bytes = 0;       // per device; 0: none but the device's memory
  size_t peak_held_bytes = 0;    // blocks in use plus cached, at their most
  size_t peak_in_use_bytes = 0;
  size_t blocks_made = 0;        // cudaMalloc calls
  size_t blocks_reused = 0;      // requests served from the cache
  size_t blocks_trimmed = 0;     // cached blocks given back to stay within the budget
  size_t matcher_fallbacks = 0;  // GPU matchers that went on on the CPU (NoteMatcherFallback)
  int devices = 0;
};

class RunGpuResources {
 public:
  // `budget_bytes` per device, 0 for none.
  explicit RunGpuResources(size_t budget_bytes);
  ~RunGpuResources();
  RunGpuResources(const RunGpuResources&) = delete;
  RunGpuResources& operator=(const RunGpuResources&) = delete;

  // The owner of device `gpu_index`'s memory (null in a build without CUDA).
  std::shared_ptr<cuda::GpuResources> ForDevice(int gpu_index);
  // A GPU matcher of the run ran out of device memory and went on on the
  // CPU (CreateFallbackFeatureMatcher); any thread.
  void NoteMatcherFallback();
  RunGpuMemoryBooks Books() const;

 private:
  const size_t budget_bytes_;
  size_t matcher_fallbacks_ = 0;  // under mutex_
  mutable std::mutex mutex_;
  std::map<int, std::shared_ptr<cuda::GpuResources>> devices_;
};

}  // namespace colmap
}  // namespace cashash
