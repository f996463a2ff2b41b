// Error checking for CUDA runtime calls. Every failure becomes a
// std::runtime_error naming the call site, so a bad launch or an exhausted
// device is reported where it happened instead of at some later sync; an
// exhausted device (cudaErrorMemoryAllocation) becomes a DeviceMemoryError,
// which every GPU part of a run answers by going on on the CPU.
#pragma once

#include <cuda_runtime.h>

#include <stdexcept>
#include <string>

#include "cashash/base/device_memory_error.h"

namespace cashash {
namespace cuda {

inline void ThrowCudaError(cudaError_t error, const char* file, int line, const char* what) {
  const std::string message =
      std::string(file) + ":" + std::to_string(line) + ": " + cudaGetErrorString(error) + " (" + what + ")";
  if (error == cudaErrorMemoryAllocation) {
    (void)cudaGetLastError();  // not a sticky error: clear it, the device goes on
    throw DeviceMemoryError(message);
  }
  throw std::runtime_error(message);
}

}  // namespace cuda
}  // namespace cashash

// Throws std::runtime_error("file:line: <CUDA message> (<call>)") on failure.
#define CUDA_CHECK(call)                                                        \
  do {                                                                          \
    const cudaError_t cashash_cuda_error_ = (call);                             \
    if (cashash_cuda_error_ != cudaSuccess) {                                   \
      ::cashash::cuda::ThrowCudaError(cashash_cuda_error_, __FILE__, __LINE__, #call); \
    }                                                                           \
  } while (0)

// Checks the launch configuration of the kernel just launched (asynchronous
// faults surface at the next synchronising CUDA_CHECK).
#define CUDA_CHECK_LAUNCH() CUDA_CHECK(cudaGetLastError())
