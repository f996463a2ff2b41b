// What this build of cashash is: its version and the GPU code it carries.
// `cashash --version`, the first lines of a run and cashash.build_info()
// report it.
#pragma once

#include <string>
#include <vector>

namespace cashash {
namespace colmap {

struct BuildInfo {
  std::string version;                // "0.1.0"
  bool cuda = false;                  // the CUDA backend is compiled in
  std::vector<int> cuda_sass;         // SASS architectures, e.g. 75 for sm_75
  std::vector<int> cuda_ptx;          // PTX architectures, e.g. 90 for compute_90
  std::string cuda_architectures;     // "SASS sm_75 ..., PTX compute_90"; "none" without CUDA
};

BuildInfo GetBuildInfo();

// "cashash 0.1.0, CUDA architectures: SASS sm_75 sm_80, PTX compute_90"
// (or "..., built without CUDA").
std::string BuildInfoLine();

}  // namespace colmap
}  // namespace cashash
