// The MPI implementation of ProcessGroup (mpi_world.h). Built only with MPI
// and linked only into the `cashash` executable, so that the library and
// the Python module run where no MPI library is installed.
#pragma once

#include <memory>

#include "distributed/mpi_world.h"

namespace cashash {
namespace distributed {

// MPI is initialised on first use, and only when the process was launched
// by mpirun / mpiexec (their environment variables say so); otherwise the
// group is a world of one.
std::unique_ptr<ProcessGroup> CreateMpiProcessGroup();

}  // namespace distributed
}  // namespace cashash
