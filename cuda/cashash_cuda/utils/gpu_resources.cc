#include "cashash_cuda/utils/gpu_resources.h"

#include <cuda_runtime.h>

#include <algorithm>

#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/device_scope.cuh"

namespace cashash {
namespace cuda {

class GpuResources::DeviceSource : public BlockSource {
 public:
  explicit DeviceSource(int device) : device_(device) {}
  void* Allocate(size_t bytes) override {
    DeviceScope scope(device_);
    void* block = nullptr;
    const cudaError_t error = cudaMalloc(&block, bytes);
    if (error == cudaErrorMemoryAllocation) {
      (void)cudaGetLastError();  // not sticky: the device goes on
      return nullptr;
    }
    CUDA_CHECK(error);
    return block;
  }
  void Free(void* block) override {
    DeviceScope::Quietly(device_, [block] { cudaFree(block); });
  }

 private:
  const int device_;
};

class GpuResources::PinnedSource : public BlockSource {
 public:
  explicit PinnedSource(int device) : device_(device) {}
  void* Allocate(size_t bytes) override {
    DeviceScope scope(device_);
    void* block = nullptr;
    const cudaError_t error = cudaHostAlloc(&block, bytes, cudaHostAllocMapped | cudaHostAllocPortable);
    if (error == cudaErrorMemoryAllocation) {
      (void)cudaGetLastError();
      return nullptr;
    }
    CUDA_CHECK(error);
    return block;
  }
  void Free(void* block) override {
    DeviceScope::Quietly(device_, [block] { cudaFreeHost(block); });
  }

 private:
  const int device_;
};

GpuResources::GpuResources(int device, size_t budget_bytes)
    : device_(device),
      budget_(budget_bytes),
      device_source_(std::make_unique<DeviceSource>(device)),
      pinned_source_(std::make_unique<PinnedSource>(device)),
      device_memory_(device_source_.get(), budget_bytes, "GPU memory"),
      // One allocation per pinned block: its device address is asked for.
      pinned_memory_(pinned_source_.get(), 0, "pinned host memory", /*slabs=*/false) {}

GpuResources::~GpuResources() = default;

size_t GpuResources::ScratchBytes() const {
  constexpr size_t kUnbudgetedScratch = size_t{1} << 30;
  return budget_ == 0 ? kUnbudgetedScratch : std::min(kUnbudgetedScratch, budget_ / 32);
}

void* GpuResources::AllocateDevice(size_t bytes, const char* what) { return device_memory_.Acquire(bytes, what); }

void GpuResources::FreeDevice(void* block) { device_memory_.Release(block); }

void GpuResources::SynchronizeDevice() {
  DeviceScope scope(device_);
  CUDA_CHECK(cudaDeviceSynchronize());
}

void* GpuResources::AllocatePinned(size_t bytes, const char* what) { return pinned_memory_.Acquire(bytes, what); }

void GpuResources::FreePinned(void* block) { pinned_memory_.Release(block); }

void* GpuResources::DevicePointerOfPinned(void* block) const {
  if (block == nullptr) return nullptr;
  void* device_pointer = nullptr;
  CUDA_CHECK(cudaHostGetDevicePointer(&device_pointer, block, 0));
  return device_pointer;
}

}  // namespace cuda
}  // namespace cashash
