#include "distributed/mpi_world.h"

#include <cstdlib>
#include <iostream>
#include <stdexcept>
#include <utility>

namespace cashash {
namespace distributed {
namespace {

std::unique_ptr<ProcessGroup>& InstalledGroup() {
  static std::unique_ptr<ProcessGroup> group;
  return group;
}

ProcessGroup* Group() { return InstalledGroup().get(); }

}  // namespace

void InstallProcessGroup(std::unique_ptr<ProcessGroup> group) { InstalledGroup() = std::move(group); }

int MpiRank() { return Group() ? Group()->Rank() : 0; }
int MpiSize() { return Group() ? Group()->Size() : 1; }

void MpiBarrier() {
  if (Group()) Group()->Barrier();
}

uint64_t MpiMin(uint64_t value) { return Group() ? Group()->Min(value) : value; }
uint64_t MpiMax(uint64_t value) { return Group() ? Group()->Max(value) : value; }

void MpiSendBytes(const std::vector<uint8_t>& bytes, int destination, int tag) {
  if (!Group()) throw std::logic_error("MpiSendBytes without MPI");
  Group()->SendBytes(bytes, destination, tag);
}

std::vector<uint8_t> MpiReceiveAny(int* source, int* tag) {
  if (!Group()) throw std::logic_error("MpiReceiveAny without MPI");
  return Group()->ReceiveAny(source, tag);
}

void MpiAbortJob(const std::string& message) {
  if (Group()) Group()->AbortJob(message);
  std::cerr << "ERROR: " << message << std::endl;
  std::abort();
}

int MpiLocalRank() { return Group() ? Group()->LocalRank() : 0; }

}  // namespace distributed
}  // namespace cashash
