// The few MPI operations cashash needs, usable whether or not MPI was built
// in. MPI is started on first use, and only when the process was launched
// by mpirun / mpiexec (their environment variables say so); otherwise, and
// without MPI support, this is a world of one process and every collective
// is a no-op.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace cashash {
namespace colmap {

int MpiRank();
int MpiSize();
// Rank on this machine, from the launcher (0 when unknown).
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

}  // namespace colmap
}  // namespace cashash
