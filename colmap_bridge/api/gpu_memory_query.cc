#include "colmap_bridge/api/gpu_memory_query.h"

#ifdef CASHASH_WITH_CUDA
#include <cuda_runtime.h>
#endif

namespace cashash {
namespace colmap {

size_t GpuFreeMemoryBytes(int gpu_index) {
  size_t free_bytes = 0, total_bytes = 0;
  return GpuMemoryInfo(gpu_index, &free_bytes, &total_bytes) ? free_bytes : 0;
}

bool GpuMemoryInfo(int gpu_index, size_t* free_bytes, size_t* total_bytes) {
  *free_bytes = 0;
  *total_bytes = 0;
#ifdef CASHASH_WITH_CUDA
  int previous = 0;
  if (cudaGetDevice(&previous) != cudaSuccess) {
    (void)cudaGetLastError();
    return false;
  }
  const bool ok = cudaSetDevice(gpu_index) == cudaSuccess && cudaMemGetInfo(free_bytes, total_bytes) == cudaSuccess;
  cudaSetDevice(previous);
  if (!ok) {
    (void)cudaGetLastError();
    *free_bytes = 0;
    *total_bytes = 0;
  }
  return ok;
#else
  (void)gpu_index;
  return false;
#endif
}

}  // namespace colmap
}  // namespace cashash
