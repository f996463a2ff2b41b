// The few MPI operations cashash needs, usable whether or not MPI is linked
// in. Only the `cashash` executable links MPI: it installs an MPI process
// group at start (mpi_process_group.h), which starts MPI on first use when
// the executable says it was launched by mpirun / mpiexec. The library and
// the Python module never load libmpi: without an installed group this is
// a world of one process and every collective is a no-op.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace cashash {
namespace distributed {

// What a message-passing library provides to the functions below.
class ProcessGroup {
 public:
  virtual ~ProcessGroup() = default;
  virtual int Rank() = 0;
  virtual int Size() = 0;
  // Rank among the processes on this machine.
  virtual int LocalRank() = 0;
  virtual void Barrier() = 0;
  virtual uint64_t Min(uint64_t value) = 0;
  virtual uint64_t Max(uint64_t value) = 0;
  virtual void SendBytes(const std::vector<uint8_t>& bytes, int destination, int tag) = 0;
  virtual std::vector<uint8_t> ReceiveAny(int* source, int* tag) = 0;
  [[noreturn]] virtual void AbortJob(const std::string& message) = 0;
};

// Called once, before any other thread starts (the executable's main).
void InstallProcessGroup(std::unique_ptr<ProcessGroup> group);

int MpiRank();
int MpiSize();
// Rank among the processes on this machine (0 without MPI).
int MpiLocalRank();

void MpiBarrier();
uint64_t MpiMin(uint64_t value);
uint64_t MpiMax(uint64_t value);

// Blocking send of `bytes` with `tag` (tags >= 0).
void MpiSendBytes(const std::vector<uint8_t>& bytes, int destination, int tag);
// Blocking receive of the next message from any rank with any tag.
std::vector<uint8_t> MpiReceiveAny(int* source, int* tag);

// Prints "ERROR: [rank r] message" and ends every process of the job.
[[noreturn]] void MpiAbortJob(const std::string& message);

}  // namespace distributed
}  // namespace cashash
