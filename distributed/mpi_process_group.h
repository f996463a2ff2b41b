// The MPI implementation of ProcessGroup (mpi_world.h). Built only with MPI
// and linked only into the `cashash` executable, so that the library and
// the Python module run where no MPI library is installed.
#pragma once

#include <memory>

#include "distributed/mpi_world.h"

namespace cashash {
namespace distributed {

// How the executable was started: by an MPI launcher (mpirun, mpiexec,
// srun) or on its own. Only the executable can tell (its launcher's
// variables, main.cc); the group never reads the environment.
enum class ProcessLaunch { kStandalone, kMpiLauncher };

// MPI is initialised on first use, and only under an MPI launcher; a
// standalone process is a world of one and never starts MPI (starting it
// alone, as an MPI singleton, costs Open MPI 4.1 about 0.35 s).
std::unique_ptr<ProcessGroup> CreateMpiProcessGroup(ProcessLaunch launch);

}  // namespace distributed
}  // namespace cashash
