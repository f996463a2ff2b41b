// What a GPU matcher is set up with beyond the matching options: its
// device, its share of device memory and which cascade kernels it runs.
// Given to the matcher's constructor (CreateGpuFeatureMatcher); the run
// fills it from the resolved run (colmap_bridge/api/matcher_factory.cc).
// Plain C++ header.
#pragma once

#include <cstddef>
#include <memory>

#include "cashash_cuda/utils/gpu_resources.h"

namespace cashash {
namespace cuda {

// The cascade's matching kernels: the bucket-tile kernels, or the older
// per-query kernel, which the GPU tests keep as the tile kernels' oracle
// (both give identical matches).
enum class GpuCascadeKernel { kBucketTiles, kPerQuery };

struct GpuMatcherConfig {
  int gpu_index = 0;
  // The owner of the device's memory (gpu_resources.h), shared with the
  // run's other GPU parts; its budget is the matcher's. Null: the matcher
  // makes one of its own with memory_budget_bytes.
  std::shared_ptr<GpuResources> resources;
  // Without `resources`: most bytes the matcher may take on the device
  // (--max_gpu_memory); past it adding an image throws DeviceMemoryError,
  // as a failed allocation does. 0: no cap but the device's own memory.
  size_t memory_budget_bytes = 0;
  GpuCascadeKernel cascade_kernel = GpuCascadeKernel::kBucketTiles;
};

}  // namespace cuda
}  // namespace cashash
