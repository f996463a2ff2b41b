// Free memory of a CUDA device, for the default --max_gpu_memory.
#pragma once

#include <cstddef>

namespace cashash {
namespace colmap {

// Bytes free on device gpu_index now; 0 when CUDA is not built or the
// device cannot be queried.
size_t GpuFreeMemoryBytes(int gpu_index);

}  // namespace colmap
}  // namespace cashash
