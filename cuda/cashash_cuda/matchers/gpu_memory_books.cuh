// A GPU matcher's own count of the device memory it holds against its
// budget (GpuResources::budget_bytes): its images and its matching scratch
// count together, so that one budget bounds both. Shared by the parts of a
// matcher (the image store and the batches), used by one thread at a time.
#pragma once

#include <cstddef>
#include <string>

#include "cashash/base/device_memory_error.h"
#include "cashash_cuda/utils/device_memory.cuh"

namespace cashash {
namespace cuda {

class GpuMemoryBooks {
 public:
  // 0: no cap but the device's own memory.
  explicit GpuMemoryBooks(size_t budget_bytes) : budget_(MemoryBudget(budget_bytes)) {}

  // Accounts for `bytes` more, or throws DeviceMemoryError naming `what`.
  void Reserve(size_t bytes, const std::string& what) {
    if (bytes > budget_ || used_ > budget_ - bytes) {
      throw DeviceMemoryError("GPU memory budget exceeded by " + what + ": it needs " + MiB(bytes) + ", " +
                              MiB(used_) + " of " + MiB(budget_) +
                              " are in use; match fewer or smaller images per block");
    }
    used_ += bytes;
  }
  void Release(size_t bytes) { used_ -= bytes; }

  size_t used() const { return used_; }
  size_t budget() const { return budget_; }
  bool capped() const { return budget_ != MemoryBudget(0); }

 private:
  const size_t budget_;
  size_t used_ = 0;
};

}  // namespace cuda
}  // namespace cashash
