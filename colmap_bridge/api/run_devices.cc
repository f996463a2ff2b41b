#include "colmap_bridge/api/run_devices.h"

#include <stdexcept>

#include "distributed/mpi_world.h"
#ifdef CASHASH_WITH_CUDA
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#endif

namespace cashash {
namespace colmap {

RunDevices ChooseRunDevices(const MatcherCommandOptions& options, const DeviceFacts& machine) {
  RunDevices devices;
  if (!options.use_gpu) return devices;
  if (!machine.cuda_built) {
    devices.warnings.push_back("cashash was built without CUDA; matching on the CPU");
    return devices;
  }
  std::vector<int> listed;
  const std::string problem = ParseGpuIndices(options.gpu_index, &listed);
  if (!problem.empty()) throw std::invalid_argument(problem);
  // Ranks sharing a machine share its GPUs unless a device is named.
  if (machine.num_ranks > 1 && options.gpu_index == "-1" && machine.num_devices > 1) {
    listed = {machine.local_rank % machine.num_devices};
  }
  std::string reasons;
  for (const int gpu_index : listed) {
    std::string why;
    if (machine.usable && machine.usable(gpu_index, &why)) {
      devices.gpu_indices.push_back(gpu_index);
    } else {
      reasons += (reasons.empty() ? "" : "; ") + std::string("device ") + std::to_string(gpu_index) + ": " + why;
    }
  }
  if (devices.gpu_indices.empty()) {
    devices.warnings.push_back("no usable CUDA device (" + reasons + "); matching on the CPU");
  } else if (!reasons.empty()) {
    devices.warnings.push_back("not every listed GPU is usable (" + reasons + "); matching on the others");
  }
  return devices;
}

DeviceFacts MachineDeviceFacts() {
  DeviceFacts machine;
  machine.local_rank = distributed::MpiLocalRank();
  machine.num_ranks = distributed::MpiSize();
#ifdef CASHASH_WITH_CUDA
  machine.cuda_built = true;
  machine.num_devices = cuda::NumCudaDevices();
  machine.usable = [](int gpu_index, std::string* reason) { return cuda::CudaDeviceUsable(gpu_index, reason); };
#endif
  return machine;
}

}  // namespace colmap
}  // namespace cashash
