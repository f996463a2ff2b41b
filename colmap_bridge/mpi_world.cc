#include "colmap_bridge/mpi_world.h"

#include <cstdlib>
#include <iostream>
#include <limits>
#include <mutex>
#include <stdexcept>

#ifdef CASHASH_WITH_MPI
#include <mpi.h>
#endif

namespace cashash {
namespace colmap {
namespace {

int EnvInt(const char* name, int fallback) {
  const char* value = std::getenv(name);
  return value != nullptr && *value != '\0' ? std::atoi(value) : fallback;
}

#ifdef CASHASH_WITH_MPI
// Open MPI, MPICH / Intel MPI (Hydra) and PMIx launchers.
bool LaunchedByMpi() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "MPI_LOCALNRANKS"}) {
    if (std::getenv(name) != nullptr) return true;
  }
  return false;
}

struct World {
  int rank = 0;
  int size = 1;
  bool active = false;
};

void FinalizeAtExit() {
  int finalized = 0;
  MPI_Finalized(&finalized);
  if (!finalized) MPI_Finalize();
}

const World& GetWorld() {
  static World world;
  static std::once_flag once;
  std::call_once(once, []() {
    if (!LaunchedByMpi()) return;
    int initialized = 0;
    MPI_Initialized(&initialized);
    if (!initialized) {
      // Rank 0 receives on one thread while its pipeline runs, ranks > 0
      // send from the pipeline's writer thread: one thread at a time.
      int provided = 0;
      MPI_Init_thread(nullptr, nullptr, MPI_THREAD_SERIALIZED, &provided);
      if (provided < MPI_THREAD_SERIALIZED) {
        throw std::runtime_error("the MPI library does not support MPI_THREAD_SERIALIZED");
      }
      std::atexit(FinalizeAtExit);
    }
    MPI_Comm_rank(MPI_COMM_WORLD, &world.rank);
    MPI_Comm_size(MPI_COMM_WORLD, &world.size);
    world.active = world.size > 1;
  });
  return world;
}
#endif

}  // namespace

#ifdef CASHASH_WITH_MPI

int MpiRank() { return GetWorld().rank; }
int MpiSize() { return GetWorld().size; }

void MpiBarrier() {
  if (GetWorld().active) MPI_Barrier(MPI_COMM_WORLD);
}

uint64_t MpiMin(uint64_t value) {
  if (!GetWorld().active) return value;
  uint64_t result = value;
  MPI_Allreduce(&value, &result, 1, MPI_UINT64_T, MPI_MIN, MPI_COMM_WORLD);
  return result;
}

uint64_t MpiMax(uint64_t value) {
  if (!GetWorld().active) return value;
  uint64_t result = value;
  MPI_Allreduce(&value, &result, 1, MPI_UINT64_T, MPI_MAX, MPI_COMM_WORLD);
  return result;
}

void MpiSendBytes(const std::vector<uint8_t>& bytes, int destination, int tag) {
  if (bytes.size() > static_cast<size_t>(std::numeric_limits<int>::max())) {
    throw std::runtime_error("MPI message of " + std::to_string(bytes.size()) + " bytes is too large");
  }
  MPI_Send(bytes.data(), static_cast<int>(bytes.size()), MPI_BYTE, destination, tag, MPI_COMM_WORLD);
}

std::vector<uint8_t> MpiReceiveAny(int* source, int* tag) {
  MPI_Status status;
  MPI_Probe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &status);
  int count = 0;
  MPI_Get_count(&status, MPI_BYTE, &count);
  std::vector<uint8_t> bytes(static_cast<size_t>(count));
  MPI_Recv(bytes.data(), count, MPI_BYTE, status.MPI_SOURCE, status.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
  *source = status.MPI_SOURCE;
  *tag = status.MPI_TAG;
  return bytes;
}

void MpiAbortJob(const std::string& message) {
  std::cout.flush();
  std::cerr << "ERROR: [rank " << MpiRank() << "] " << message << std::endl;
  MPI_Abort(MPI_COMM_WORLD, 1);
  std::abort();
}

#else  // no MPI: a world of one

int MpiRank() { return 0; }
int MpiSize() { return 1; }
void MpiBarrier() {}
uint64_t MpiMin(uint64_t value) { return value; }
uint64_t MpiMax(uint64_t value) { return value; }
void MpiSendBytes(const std::vector<uint8_t>&, int, int) {
  throw std::logic_error("MpiSendBytes without MPI");
}
std::vector<uint8_t> MpiReceiveAny(int*, int*) { throw std::logic_error("MpiReceiveAny without MPI"); }
void MpiAbortJob(const std::string& message) {
  std::cerr << "ERROR: " << message << std::endl;
  std::abort();
}

#endif

int MpiLocalRank() {
  return EnvInt("OMPI_COMM_WORLD_LOCAL_RANK", EnvInt("MPI_LOCALRANKID", EnvInt("PMI_LOCAL_RANK", 0)));
}

}  // namespace colmap
}  // namespace cashash
