// RAII handles of device and pinned host memory, all taken from the
// device's GpuResources (gpu_resources.h), which keeps the books and the
// budget. Allocation failures throw DeviceMemoryError naming what was
// allocated.
#pragma once

#include <cuda_runtime.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/gpu_resources.h"

namespace cashash {
namespace cuda {

inline std::string MiB(size_t bytes) { return std::to_string((bytes + (1u << 20) - 1) >> 20) + " MiB"; }

// The cap a matcher checks its device memory against: `budget_bytes`
// (GpuMatcherConfig::memory_budget_bytes), or with 0 none but the device's
// own memory (allocations that fail throw).
inline size_t MemoryBudget(size_t budget_bytes) {
  return budget_bytes == 0 ? std::numeric_limits<size_t>::max() : budget_bytes;
}

// Device memory from a GpuResources (gpu_resources.h); move-only. Release
// waits for the device first, as the cudaFree it replaces did: a buffer
// does not know which streams still read it, and its block may go to
// another user of the device at once.
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  DeviceBuffer(GpuResources* owner, size_t bytes, const char* what) { Allocate(owner, bytes, what); }
  ~DeviceBuffer() { Release(); }
  DeviceBuffer(DeviceBuffer&& o) noexcept
      : owner_(std::exchange(o.owner_, nullptr)), ptr_(std::exchange(o.ptr_, nullptr)), bytes_(std::exchange(o.bytes_, 0)) {}
  DeviceBuffer& operator=(DeviceBuffer&& o) noexcept {
    if (this != &o) {
      Release();
      owner_ = std::exchange(o.owner_, nullptr);
      ptr_ = std::exchange(o.ptr_, nullptr);
      bytes_ = std::exchange(o.bytes_, 0);
    }
    return *this;
  }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;

  // Throws DeviceMemoryError when the owner has no room.
  void Allocate(GpuResources* owner, size_t bytes, const char* what) {
    Release();
    if (bytes == 0) return;
    ptr_ = owner->AllocateDevice(bytes, what);
    owner_ = owner;
    bytes_ = bytes;
  }
  void Release() {
    if (ptr_ != nullptr) {
      try {
        owner_->SynchronizeDevice();
      } catch (const std::exception&) {
        // a failed device: its errors surface at the next checked call
      }
      owner_->FreeDevice(ptr_);
    }
    ptr_ = nullptr;
    bytes_ = 0;
  }
  template <typename T>
  T* as() const { return static_cast<T*>(ptr_); }
  size_t bytes() const { return bytes_; }

 private:
  GpuResources* owner_ = nullptr;
  void* ptr_ = nullptr;
  size_t bytes_ = 0;
};

// A block of a GpuResources that its user knows to be idle when it goes
// (the images of the matchers, which the exact-matching tickets may hold a
// while longer on another thread): given back without waiting for the
// device. The owner outlives the block (the users hold it by shared_ptr).
class PooledDeviceBlock {
 public:
  PooledDeviceBlock() = default;
  PooledDeviceBlock(GpuResources* owner, size_t bytes, const char* what)
      : owner_(owner), ptr_(owner->AllocateDevice(bytes, what)), bytes_(bytes) {}
  ~PooledDeviceBlock() { Reset(); }
  PooledDeviceBlock(PooledDeviceBlock&& o) noexcept
      : owner_(std::exchange(o.owner_, nullptr)), ptr_(std::exchange(o.ptr_, nullptr)), bytes_(std::exchange(o.bytes_, 0)) {}
  PooledDeviceBlock& operator=(PooledDeviceBlock&& o) noexcept {
    if (this != &o) {
      Reset();
      owner_ = std::exchange(o.owner_, nullptr);
      ptr_ = std::exchange(o.ptr_, nullptr);
      bytes_ = std::exchange(o.bytes_, 0);
    }
    return *this;
  }
  PooledDeviceBlock(const PooledDeviceBlock&) = delete;
  PooledDeviceBlock& operator=(const PooledDeviceBlock&) = delete;
  template <typename T>
  T* as() const { return static_cast<T*>(ptr_); }
  // The bytes asked for (the owner's size class may be larger).
  size_t bytes() const { return bytes_; }

 private:
  void Reset() {
    if (ptr_ != nullptr) owner_->FreeDevice(ptr_);
    ptr_ = nullptr;
  }
  GpuResources* owner_ = nullptr;
  void* ptr_ = nullptr;
  size_t bytes_ = 0;
};

// Page-locked host memory of a GpuResources, mapped into the device address
// space so kernels can write results straight into it. Release waits for
// the device first, as cudaFreeHost did.
class PinnedBuffer {
 public:
  PinnedBuffer() = default;
  ~PinnedBuffer() { Release(); }
  PinnedBuffer(const PinnedBuffer&) = delete;
  PinnedBuffer& operator=(const PinnedBuffer&) = delete;

  // Throws DeviceMemoryError when no more host memory can be pinned.
  void Allocate(GpuResources* owner, size_t bytes, const char* what) {
    Release();
    if (bytes == 0) return;
    ptr_ = owner->AllocatePinned(bytes, what);
    owner_ = owner;
    bytes_ = bytes;
    device_ptr_ = owner->DevicePointerOfPinned(ptr_);
  }
  void Release() {
    if (ptr_ != nullptr) {
      try {
        owner_->SynchronizeDevice();
      } catch (const std::exception&) {
        // a failed device: its errors surface at the next checked call
      }
      owner_->FreePinned(ptr_);
    }
    ptr_ = nullptr;
    device_ptr_ = nullptr;
    bytes_ = 0;
  }
  template <typename T>
  T* host() const { return static_cast<T*>(ptr_); }
  template <typename T>
  T* device() const { return static_cast<T*>(device_ptr_); }
  size_t bytes() const { return bytes_; }

 private:
  GpuResources* owner_ = nullptr;
  void* ptr_ = nullptr;
  void* device_ptr_ = nullptr;
  size_t bytes_ = 0;
};

// Host-to-device copies through a ring of pinned staging buffers: Upload
// returns once the bytes are copied on the host, without waiting for the
// device, and a buffer is reused once its copy is done. A pageable
// cudaMemcpy and its wait were most of what adding an image cost. Make it
// with the device current; one thread at a time.
class PinnedUploadRing {
 public:
  static constexpr int kSlots = 4;

  explicit PinnedUploadRing(GpuResources* owner) : owner_(owner) {
    for (Slot& slot : slots_) CUDA_CHECK(cudaEventCreateWithFlags(&slot.uploaded, cudaEventDisableTiming));
  }
  ~PinnedUploadRing() {
    for (Slot& slot : slots_) {
      if (slot.uploaded != nullptr) {
        cudaEventSynchronize(slot.uploaded);  // the copy still reads the buffer
        cudaEventDestroy(slot.uploaded);
      }
    }
  }
  PinnedUploadRing(const PinnedUploadRing&) = delete;
  PinnedUploadRing& operator=(const PinnedUploadRing&) = delete;

  // Copies `bytes` from `host` to `device` on `stream`: ordered before what
  // is enqueued on that stream later.
  void Upload(const void* host, size_t bytes, void* device, cudaStream_t stream) {
    Slot& slot = slots_[next_];
    next_ = (next_ + 1) % kSlots;
    if (slot.in_flight) CUDA_CHECK(cudaEventSynchronize(slot.uploaded));
    if (slot.buffer.bytes() < bytes) slot.buffer.Allocate(owner_, bytes, "upload staging");
    std::memcpy(slot.buffer.host<uint8_t>(), host, bytes);
    CUDA_CHECK(cudaMemcpyAsync(device, slot.buffer.host<uint8_t>(), bytes, cudaMemcpyHostToDevice, stream));
    CUDA_CHECK(cudaEventRecord(slot.uploaded, stream));
    slot.in_flight = true;
  }

 private:
  struct Slot {
    PinnedBuffer buffer;
    cudaEvent_t uploaded = nullptr;
    bool in_flight = false;
  };
  GpuResources* owner_;
  Slot slots_[kSlots];
  int next_ = 0;
};

}  // namespace cuda
}  // namespace cashash
