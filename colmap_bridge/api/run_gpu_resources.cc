#include "colmap_bridge/api/run_gpu_resources.h"

#include <algorithm>

#ifdef CASHASH_WITH_CUDA
#include "cashash_cuda/utils/gpu_resources.h"
#endif

namespace cashash {
namespace colmap {

RunGpuResources::RunGpuResources(size_t budget_bytes) : budget_bytes_(budget_bytes) {}

RunGpuResources::~RunGpuResources() = default;

std::shared_ptr<cuda::GpuResources> RunGpuResources::ForDevice(int gpu_index) {
#ifdef CASHASH_WITH_CUDA
  std::lock_guard<std::mutex> lock(mutex_);
  std::shared_ptr<cuda::GpuResources>& owner = devices_[gpu_index];
  if (!owner) owner = std::make_shared<cuda::GpuResources>(gpu_index, budget_bytes_);
  return owner;
#else
  (void)gpu_index;
  return nullptr;
#endif
}

void RunGpuResources::NoteMatcherFallback() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++matcher_fallbacks_;
}

RunGpuMemoryBooks RunGpuResources::Books() const {
  std::lock_guard<std::mutex> lock(mutex_);
  RunGpuMemoryBooks books;
  books.budget_bytes = budget_bytes_;
  books.matcher_fallbacks = matcher_fallbacks_;
#ifdef CASHASH_WITH_CUDA
  for (const auto& [device, owner] : devices_) {
    const BlockAllocatorStats stats = owner->DeviceStats();
    books.peak_held_bytes = std::max(books.peak_held_bytes, stats.peak_held_bytes);
    books.peak_in_use_bytes = std::max(books.peak_in_use_bytes, stats.peak_in_use_bytes);
    books.blocks_made += stats.source_allocations;
    books.blocks_reused += stats.reuses;
    books.blocks_trimmed += stats.trimmed_blocks;
    ++books.devices;
  }
#endif
  return books;
}

}  // namespace colmap
}  // namespace cashash
