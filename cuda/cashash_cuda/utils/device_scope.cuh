// Makes a device current for a scope and restores the caller's device, so
// that a part working on the device of its resources leaves the calling
// thread's device as it found it.
#pragma once

#include <cuda_runtime.h>

#include "cashash_cuda/utils/cuda_check.cuh"

namespace cashash {
namespace cuda {

class DeviceScope {
 public:
  explicit DeviceScope(int device) {
    CUDA_CHECK(cudaGetDevice(&previous_));
    if (previous_ != device) CUDA_CHECK(cudaSetDevice(device));
  }
  ~DeviceScope() { cudaSetDevice(previous_); }
  // Runs `free` with `device` current; never throws (it runs in destructors).
  template <typename Free>
  static void Quietly(int device, Free free) {
    int previous = 0;
    if (cudaGetDevice(&previous) != cudaSuccess) previous = device;
    cudaSetDevice(device);
    free();
    cudaSetDevice(previous);
    (void)cudaGetLastError();
  }
  DeviceScope(const DeviceScope&) = delete;
  DeviceScope& operator=(const DeviceScope&) = delete;

 private:
  int previous_ = 0;
};

}  // namespace cuda
}  // namespace cashash
