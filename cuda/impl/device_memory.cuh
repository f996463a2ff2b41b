// RAII owners of device and pinned host memory. Allocation failures throw
// std::runtime_error with the requested size so that out-of-memory cases are
// reported clearly instead of crashing later.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include "utils/cuda_check.cuh"

namespace cashash {
namespace cuda {

inline std::string MiB(size_t bytes) { return std::to_string((bytes + (1u << 20) - 1) >> 20) + " MiB"; }

// Optional cap on the device memory a matcher uses, for tests and shared
// devices: CASHASH_GPU_MEMORY_LIMIT_MB. Without it the device's own limit
// applies (allocations that fail throw).
inline size_t MemoryBudgetFromEnvironment() {
  const char* value = std::getenv("CASHASH_GPU_MEMORY_LIMIT_MB");
  if (value == nullptr || *value == '\0') return std::numeric_limits<size_t>::max();
  return static_cast<size_t>(std::strtoull(value, nullptr, 10)) << 20;
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

}  // namespace cuda
}  // namespace cashash
