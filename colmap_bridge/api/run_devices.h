// Which GPUs a run matches and verifies on: the devices of
// --FeatureMatching.gpu_index that can run this build's code. Chosen once,
// before the run is resolved, so that the run is resolved with the rules of
// the devices that will match (ResolveRun), and the matchers and the
// verifier are built on exactly those (ResolvedRun::gpu_indices).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "colmap_bridge/api/command_options.h"

namespace cashash {
namespace colmap {

// What the machine says about its GPUs (MachineDeviceFacts); tests write
// them by hand.
struct DeviceFacts {
  // cashash was built with the CUDA backend.
  bool cuda_built = false;
  int num_devices = 0;
  // Whether device i can run this build's code; else *reason says why.
  std::function<bool(int, std::string*)> usable;
  // Under MPI: this process's rank among those on its machine, and the
  // number of ranks of the job.
  int local_rank = 0;
  int num_ranks = 1;
};

struct RunDevices {
  // The usable devices, in the order listed; empty: the CPU.
  std::vector<int> gpu_indices;
  // One line for each listed device that cannot be used, or for no GPU at
  // all where one was asked for.
  std::vector<std::string> warnings;
};

// The devices of `options` (none without use_gpu) that `machine` can use.
// Under MPI, with gpu_index -1 on a machine of several devices, each rank
// takes device local_rank % num_devices. Throws std::invalid_argument for a
// malformed gpu_index (ParseGpuIndices).
RunDevices ChooseRunDevices(const MatcherCommandOptions& options, const DeviceFacts& machine);

// This machine's devices (CUDA) and this process's MPI rank on it.
DeviceFacts MachineDeviceFacts();

}  // namespace colmap
}  // namespace cashash
