// Free memory of a CUDA device, for the default --max_gpu_memory and the
// peak a run reports.
#pragma once

#include <cstddef>

namespace cashash {
namespace colmap {

// Bytes free on device gpu_index now; 0 when CUDA is not built or the
// device cannot be queried.
size_t GpuFreeMemoryBytes(int gpu_index);

// Free and total bytes of device gpu_index (cudaMemGetInfo: the whole
// device, every process on it); false when CUDA is not built or the device
// cannot be queried.
bool GpuMemoryInfo(int gpu_index, size_t* free_bytes, size_t* total_bytes);

}  // namespace colmap
}  // namespace cashash
