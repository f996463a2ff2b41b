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

void FinalizeAtExit() {
  int finalized = 0;
  MPI_Finalized(&finalized);
  if (!finalized) MPI_Finalize();
}

class MpiProcessGroup : public ProcessGroup {
 public:
  explicit MpiProcessGroup(ProcessLaunch launch) : launch_(launch) {}

  int Rank() override { return World().rank; }
  int Size() override { return World().size; }
  int LocalRank() override { return World().local_rank; }

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
    int local_rank = 0;
    bool active = false;
  };

  const State& World() {
    std::call_once(once_, [this]() {
      if (launch_ != ProcessLaunch::kMpiLauncher) return;
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
      // The rank among the processes that share this machine's memory.
      MPI_Comm node;
      MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, state_.rank, MPI_INFO_NULL, &node);
      MPI_Comm_rank(node, &state_.local_rank);
      MPI_Comm_free(&node);
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

  const ProcessLaunch launch_;
  std::once_flag once_;
  State state_;
};

}  // namespace

std::unique_ptr<ProcessGroup> CreateMpiProcessGroup(ProcessLaunch launch) {
  return std::make_unique<MpiProcessGroup>(launch);
}

}  // namespace distributed
}  // namespace cashash
