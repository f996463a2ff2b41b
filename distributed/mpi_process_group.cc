#include "distributed/mpi_process_group.h"

#include <mpi.h>

#include <cstdlib>
#include <iostream>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>

namespace cashash {
namespace distributed {
namespace {

// Open MPI, MPICH / Intel MPI (Hydra) and PMIx launchers.
bool LaunchedByMpi() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "MPI_LOCALNRANKS"}) {
    if (std::getenv(name) != nullptr) return true;
  }
  return false;
}

void FinalizeAtExit() {
  int finalized = 0;
  MPI_Finalized(&finalized);
  if (!finalized) MPI_Finalize();
}

class MpiProcessGroup : public ProcessGroup {
 public:
  int Rank() override { return World().rank; }
  int Size() override { return World().size; }

  void Barrier() override {
    if (World().active) MPI_Barrier(MPI_COMM_WORLD);
  }

  uint64_t Min(uint64_t value) override { return Reduce(value, MPI_MIN); }
  uint64_t Max(uint64_t value) override { return Reduce(value, MPI_MAX); }

  void SendBytes(const std::vector<uint8_t>& bytes, int destination, int tag) override {
    if (bytes.size() > static_cast<size_t>(std::numeric_limits<int>::max())) {
      throw std::runtime_error("MPI message of " + std::to_string(bytes.size()) + " bytes is too large");
    }
    MPI_Send(bytes.data(), static_cast<int>(bytes.size()), MPI_BYTE, destination, tag, MPI_COMM_WORLD);
  }

  std::vector<uint8_t> ReceiveAny(int* source, int* tag) override {
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

  [[noreturn]] void AbortJob(const std::string& message) override {
    std::cout.flush();
    std::cerr << "ERROR: [rank " << Rank() << "] " << message << std::endl;
    if (World().active) MPI_Abort(MPI_COMM_WORLD, 1);
    std::abort();
  }

 private:
  struct State {
    int rank = 0;
    int size = 1;
    bool active = false;
  };

  const State& World() {
    std::call_once(once_, [this]() {
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
      MPI_Comm_rank(MPI_COMM_WORLD, &state_.rank);
      MPI_Comm_size(MPI_COMM_WORLD, &state_.size);
      state_.active = state_.size > 1;
    });
    return state_;
  }

  uint64_t Reduce(uint64_t value, MPI_Op op) {
    if (!World().active) return value;
    uint64_t result = value;
    MPI_Allreduce(&value, &result, 1, MPI_UINT64_T, op, MPI_COMM_WORLD);
    return result;
  }

  std::once_flag once_;
  State state_;
};

}  // namespace

std::unique_ptr<ProcessGroup> CreateMpiProcessGroup() { return std::make_unique<MpiProcessGroup>(); }

}  // namespace distributed
}  // namespace cashash
