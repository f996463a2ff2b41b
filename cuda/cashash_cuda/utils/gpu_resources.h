// One owner of a device's memory for a run, as faiss's StandardGpuResources
// is for its indexes: the cascade matcher's images and batch buffers, the
// exact rematch's tickets and kernels, the brute-force matchers and the
// verifier's RANSAC buffers all take their device memory (and their pinned
// host staging) from the one GpuResources of their device, under one budget,
// --max_gpu_memory.
//
// Device memory is a CachingBlockAllocator over cudaMalloc: size classes,
// freed blocks cached for the next request of their class (without a
// budget, blocks of a class share slabs of up to 32 MiB, so hundreds of
// images cost a few dozen cudaMalloc calls; under one, each block is its
// own, so that any cached block can be given back alone), cached blocks
// given back (cudaFree) when a request would pass the budget, and
// DeviceMemoryError (cashash/base/device_memory_error.h) when the blocks in
// use leave no room or cudaMalloc reports cudaErrorMemoryAllocation. Every
// user answers that error the same way: its work goes to the CPU.
//
// How the budget is shared: the run's schedule gives the cascade's images
// at most half of it, counted at their size class
// (ScheduleLimits::gpu_image_share); each of the cascade's two batch slots grows within a
// sixteenth; each rematch batch's scratch stays within ScratchBytes(), a
// thirty-second (its kernels grow their buffers by half again, and up to
// three run at once); the verifier's buffers, sized by the chunk, find the
// rest.
//
// Plain C++ header (the bridge makes one per device and run); thread-safe.
#pragma once

#include <cstddef>
#include <memory>

#include "cashash/base/caching_block_allocator.h"

namespace cashash {
namespace cuda {

class GpuResources {
 public:
  // `budget_bytes` 0: no budget but the device's memory.
  GpuResources(int device, size_t budget_bytes);
  ~GpuResources();
  GpuResources(const GpuResources&) = delete;
  GpuResources& operator=(const GpuResources&) = delete;

  int device() const { return device_; }
  // 0: none.
  size_t budget_bytes() const { return budget_; }
  // What one batch of the brute-force kernels' scratch (the exact rematch,
  // the brute-force matcher) may take: a thirty-second of the budget, at
  // most 1 GiB (the batch limit without a budget).
  size_t ScratchBytes() const;

  // Device memory of at least `bytes` (null for 0) on this device, whatever
  // device is current. Throws DeviceMemoryError naming `what`.
  void* AllocateDevice(size_t bytes, const char* what);
  // `block` from AllocateDevice, no longer used by any queued work: it goes
  // to the cache for the next request of its class.
  void FreeDevice(void* block);
  // Waits for all work of the device (as a cudaFree does), for a caller
  // that does not know which streams still use a block it frees.
  void SynchronizeDevice();

  // Page-locked host memory, mapped into the device's address space (a
  // kernel may write straight into it), cached by size class as device
  // memory is; host memory, so not under the budget. Throws
  // DeviceMemoryError when the host cannot pin more.
  void* AllocatePinned(size_t bytes, const char* what);
  void FreePinned(void* block);
  // The device address of a block of AllocatePinned.
  void* DevicePointerOfPinned(void* block) const;

  BlockAllocatorStats DeviceStats() const { return device_memory_.Stats(); }
  BlockAllocatorStats PinnedStats() const { return pinned_memory_.Stats(); }

 private:
  class DeviceSource;
  class PinnedSource;
  const int device_;
  const size_t budget_;
  std::unique_ptr<DeviceSource> device_source_;
  std::unique_ptr<PinnedSource> pinned_source_;
  CachingBlockAllocator device_memory_;
  CachingBlockAllocator pinned_memory_;
};

}  // namespace cuda
}  // namespace cashash
