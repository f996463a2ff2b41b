#include "colmap_bridge/gpu_memory_query.h"

#ifdef CASHASH_WITH_CUDA
#include <cuda_runtime.h>
#endif

namespace cashash {
namespace colmap {

size_t GpuFreeMemoryBytes(int gpu_index) {
#ifdef CASHASH_WITH_CUDA
  int previous = 0;
  if (cudaGetDevice(&previous) != cudaSuccess) return 0;
  size_t free_bytes = 0, total_bytes = 0;
  const bool ok = cudaSetDevice(gpu_index) == cudaSuccess && cudaMemGetInfo(&free_bytes, &total_bytes) == cudaSuccess;
  cudaSetDevice(previous);
  if (!ok) {
    (void)cudaGetLastError();
    return 0;
  }
  return free_bytes;
#else
  (void)gpu_index;
  return 0;
#endif
}

}  // namespace colmap
}  // namespace cashash
