// Which GPUs this binary can serve: the CUDA architectures it was compiled
// for (recorded at build time, CMake's CUDA_ARCHITECTURES syntax) and the
// rule that decides whether a device of a given compute capability can load
// any of that code. Plain C++: the decision needs no device, so it is tested
// without one; CudaDeviceUsable applies it to the device at hand.
#pragma once

#include <string>
#include <vector>

namespace cashash {
namespace cuda {

struct CudaArchitectures {
  std::vector<int> sass;  // machine code, e.g. 75 for sm_75
  std::vector<int> ptx;   // PTX the driver compiles at load time, e.g. 90 for compute_90
};

// Parses a CMake architecture list, separated by ';' or ',':
// "75-real;80-real;90" (90: SASS and PTX),
// "80-virtual" (PTX only), "90a-real" (read as 90). Entries that name no
// number ("native", "all" unresolved) are skipped.
CudaArchitectures ParseCudaArchitectures(const std::string& cmake_list);

// The architectures this binary carries.
const CudaArchitectures& CompiledCudaArchitectures();

// "SASS sm_75 sm_80 sm_86 sm_89 sm_90, PTX compute_90"; "none" when empty.
std::string DescribeCudaArchitectures(const CudaArchitectures& architectures);

// A device of compute capability major.minor runs SASS built for the same
// major and a minor not above its own (sm_80 code runs on 8.6), and PTX
// built for any compute capability not above its own (the driver compiles
// it). An empty description (unknown) is taken to fit.
bool CanRunOnDevice(const CudaArchitectures& architectures, int major, int minor);

// The one line a run prints when device gpu_index cannot load this binary's
// GPU code: the GPU, its compute capability, what the binary carries, and
// the CMake flag that builds for it.
std::string UnservableDeviceMessage(int gpu_index, const std::string& gpu_name, int major, int minor,
                                    const CudaArchitectures& architectures);

}  // namespace cuda
}  // namespace cashash
