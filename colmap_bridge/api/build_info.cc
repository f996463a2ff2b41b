#include "colmap_bridge/api/build_info.h"

#ifdef CASHASH_WITH_CUDA
#include "cashash_cuda/utils/architecture_support.h"
#endif

// CMake defines the project version for this file (colmap_bridge/CMakeLists.txt).
#ifndef CASHASH_VERSION
#define CASHASH_VERSION "unknown"
#endif

namespace cashash {
namespace colmap {

BuildInfo GetBuildInfo() {
  BuildInfo info;
  info.version = CASHASH_VERSION;
#ifdef CASHASH_WITH_CUDA
  const cuda::CudaArchitectures& compiled = cuda::CompiledCudaArchitectures();
  info.cuda = true;
  info.cuda_sass = compiled.sass;
  info.cuda_ptx = compiled.ptx;
  info.cuda_architectures = cuda::DescribeCudaArchitectures(compiled);
#else
  info.cuda_architectures = "none";
#endif
  return info;
}

std::string BuildInfoLine() {
  const BuildInfo info = GetBuildInfo();
  return "cashash " + info.version +
         (info.cuda ? ", CUDA architectures: " + info.cuda_architectures : std::string(", built without CUDA"));
}

}  // namespace colmap
}  // namespace cashash
