// RAII owners of device and pinned host memory. Allocation failures throw
// std::runtime_error with the requested size so that out-of-memory cases are
// reported clearly instead of crashing later.
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

namespace cashash {
namespace cuda {

inline std::string MiB(size_t bytes) { return std::to_string((bytes + (1u << 20) - 1) >> 20) + " MiB"; }

// The cap a matcher checks its device memory against: `budget_bytes`
// (GpuMatcherConfig::memory_budget_bytes), or with 0 none but the device's
// own memory (allocations that fail throw).
inline size_t MemoryBudget(size_t budget_bytes) {
  return budget_bytes == 0 ? std::numeric_limits<size_t>::max() : budget_bytes;
}

// Device memory; move-only.
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  explicit DeviceBuffer(size_t bytes, const char* what) { Allocate(bytes, what); }
  ~DeviceBuffer() { Release(); }
  DeviceBuffer(DeviceBuffer&& o) noexcept : ptr_(std::exchange(o.ptr_, nullptr)), bytes_(std::exchange(o.bytes_, 0)) {}
  DeviceBuffer& operator=(DeviceBuffer&& o) noexcept {
    if (this != &o) {
      Release();
      ptr_ = std::exchange(o.ptr_, nullptr);
      bytes_ = std::exchange(o.bytes_, 0);
    }
    return *this;
  }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;

  void Allocate(size_t bytes, const char* what) {
    Release();
    if (bytes == 0) return;
    const cudaError_t error = cudaMalloc(&ptr_, bytes);
    if (error != cudaSuccess) {
      (void)cudaGetLastError();  // clear the sticky-free allocation error
      ptr_ = nullptr;
      size_t free_bytes = 0, total_bytes = 0;
      cudaMemGetInfo(&free_bytes, &total_bytes);
      throw std::runtime_error(std::string("GPU out of memory allocating ") + MiB(bytes) + " for " + what +
                               " (" + MiB(free_bytes) + " free of " + MiB(total_bytes) + ")");
    }
    bytes_ = bytes;
  }
  void Release() {
    if (ptr_ != nullptr) cudaFree(ptr_);
    ptr_ = nullptr;
    bytes_ = 0;
  }
  template <typename T>
  T* as() const { return static_cast<T*>(ptr_); }
  size_t bytes() const { return bytes_; }

 private:
  void* ptr_ = nullptr;
  size_t bytes_ = 0;
};

// Device memory for many blocks of a few sizes (the images of a run):
// blocks are carved from large chunks and reused by size, so adding an image
// costs no cudaMalloc (about a third of a millisecond each on the H200,
// a third of what adding an image cost), and removing one no cudaFree,
// which would wait for every stream of the device. Memory goes back to the
// device only with the pool. Thread-safe: a block lent to another thread
// (the GPU cascade's exact-matching tickets) comes back from there.
class DeviceBlockPool {
 public:
  static constexpr size_t kChunkBytes = size_t{64} << 20;
  static constexpr size_t kAlignment = 256;

  // Throws like DeviceBuffer::Allocate when the device has no room.
  void* Acquire(size_t bytes, const char* what) {
    bytes = RoundUp(bytes);
    std::lock_guard<std::mutex> lock(mutex_);
    auto& reusable = free_[bytes];
    if (!reusable.empty()) {
      void* ptr = reusable.back();
      reusable.pop_back();
      return ptr;
    }
    if (chunks_.empty() || chunk_left_ < bytes) {
      try {
        chunks_.emplace_back(std::max(bytes, kChunkBytes), what);
      } catch (const std::runtime_error&) {
        chunks_.emplace_back(bytes, what);  // a nearly full device: this block alone
      }
      chunk_left_ = chunks_.back().bytes();
    }
    DeviceBuffer& chunk = chunks_.back();
    void* ptr = chunk.as<char>() + (chunk.bytes() - chunk_left_);
    chunk_left_ -= bytes;
    return ptr;
  }
  // `ptr` from Acquire(bytes); no kernel may use it any more.
  void Release(void* ptr, size_t bytes) {
    std::lock_guard<std::mutex> lock(mutex_);
    free_[RoundUp(bytes)].push_back(ptr);
  }

 private:
  static size_t RoundUp(size_t bytes) { return (bytes + kAlignment - 1) / kAlignment * kAlignment; }
  std::mutex mutex_;
  std::vector<DeviceBuffer> chunks_;
  size_t chunk_left_ = 0;
  std::unordered_map<size_t, std::vector<void*>> free_;
};

// One block of a DeviceBlockPool, given back when this goes.
class PooledDeviceBlock {
 public:
  PooledDeviceBlock() = default;
  PooledDeviceBlock(DeviceBlockPool* pool, size_t bytes, const char* what)
      : pool_(pool), ptr_(pool->Acquire(bytes, what)), bytes_(bytes) {}
  ~PooledDeviceBlock() { Reset(); }
  PooledDeviceBlock(PooledDeviceBlock&& o) noexcept
      : pool_(std::exchange(o.pool_, nullptr)), ptr_(std::exchange(o.ptr_, nullptr)), bytes_(std::exchange(o.bytes_, 0)) {}
  PooledDeviceBlock& operator=(PooledDeviceBlock&& o) noexcept {
    if (this != &o) {
      Reset();
      pool_ = std::exchange(o.pool_, nullptr);
      ptr_ = std::exchange(o.ptr_, nullptr);
      bytes_ = std::exchange(o.bytes_, 0);
    }
    return *this;
  }
  PooledDeviceBlock(const PooledDeviceBlock&) = delete;
  PooledDeviceBlock& operator=(const PooledDeviceBlock&) = delete;
  template <typename T>
  T* as() const { return static_cast<T*>(ptr_); }
  size_t bytes() const { return bytes_; }

 private:
  void Reset() {
    if (ptr_ != nullptr) pool_->Release(ptr_, bytes_);
    ptr_ = nullptr;
  }
  DeviceBlockPool* pool_ = nullptr;
  void* ptr_ = nullptr;
  size_t bytes_ = 0;
};

// Page-locked host memory, optionally mapped into the device address space
// so kernels can write results straight into it.
class PinnedBuffer {
 public:
  PinnedBuffer() = default;
  ~PinnedBuffer() { Release(); }
  PinnedBuffer(const PinnedBuffer&) = delete;
  PinnedBuffer& operator=(const PinnedBuffer&) = delete;

  void Allocate(size_t bytes, bool mapped, const char* what) {
    Release();
    if (bytes == 0) return;
    const cudaError_t error = cudaHostAlloc(&ptr_, bytes, mapped ? cudaHostAllocMapped : cudaHostAllocDefault);
    if (error != cudaSuccess) {
      (void)cudaGetLastError();
      ptr_ = nullptr;
      throw std::runtime_error(std::string("cannot allocate ") + MiB(bytes) + " of pinned host memory for " + what +
                               ": " + cudaGetErrorString(error));
    }
    bytes_ = bytes;
    if (mapped) CUDA_CHECK(cudaHostGetDevicePointer(&device_ptr_, ptr_, 0));
  }
  void Release() {
    if (ptr_ != nullptr) cudaFreeHost(ptr_);
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

  PinnedUploadRing() {
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
    if (slot.buffer.bytes() < bytes) slot.buffer.Allocate(bytes, /*mapped=*/false, "upload staging");
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
  Slot slots_[kSlots];
  int next_ = 0;
};

}  // namespace cuda
}  // namespace cashash
