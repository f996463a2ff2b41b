// The one error type for "the device has no room": a failed device
// allocation (cudaErrorMemoryAllocation) or an allocation past the run's
// budget (--max_gpu_memory). Callers recognise it by its type, never by the
// text of its message, and every GPU part of a run answers it the same way:
// the work goes to the CPU (IsDeviceMemoryError, fallback_feature_matcher.h).
#pragma once

#include <stdexcept>
#include <string>

namespace cashash {

class DeviceMemoryError : public std::runtime_error {
 public:
  explicit DeviceMemoryError(const std::string& what) : std::runtime_error(what) {}
};

}  // namespace cashash
