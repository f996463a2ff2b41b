// Streams of the two GPU stages of a run. Matching and verification share
// the device; matching feeds the whole pipeline and its kernels are short,
// while one RANSAC block can run for thousands of trials. Matching streams
// therefore take the highest priority, so that its blocks are scheduled as
// soon as an SM frees up instead of queueing behind a chunk's verification.
//
// The exact rematch that the cascade defers (its ticket's kernels) runs with
// matching's priority by default. CASHASH_REMATCH_PRIORITY=low puts it below
// verification instead (verification one step above the least, where the
// device has more than two levels), to compare where the rematch has a
// thread of its own (CASHASH_REMATCH_THREAD=1) and would otherwise take SMs
// ahead of the verifier call that sets the run's pace.
#pragma once

#include <cuda_runtime.h>

#include <cstdlib>
#include <cstring>

#include "cashash_cuda/utils/cuda_check.cuh"

namespace cashash {
namespace cuda {

enum class StreamRole { kMatching, kVerification, kDeferredRematch };

inline bool DeferredRematchBelowVerification() {
  static const bool low = [] {
    const char* text = std::getenv("CASHASH_REMATCH_PRIORITY");
    return text != nullptr && std::strcmp(text, "low") == 0;
  }();
  return low;
}

// The role's priority within the device's range (numerically: least >=
// greatest, and a smaller number is scheduled first); `rematch_low` as
// CASHASH_REMATCH_PRIORITY=low asks.
inline int StagePriority(StreamRole role, int least, int greatest, bool rematch_low) {
  switch (role) {
    case StreamRole::kMatching:
      return greatest;
    case StreamRole::kVerification:
      return rematch_low && least > greatest ? least - 1 : least;
    case StreamRole::kDeferredRematch:
      return rematch_low ? least : greatest;
  }
  return least;
}

// A non-blocking stream with the role's priority on the current device.
inline cudaStream_t CreateStageStream(StreamRole role) {
  int least = 0, greatest = 0;
  CUDA_CHECK(cudaDeviceGetStreamPriorityRange(&least, &greatest));
  cudaStream_t stream = nullptr;
  CUDA_CHECK(cudaStreamCreateWithPriority(&stream, cudaStreamNonBlocking,
                                          StagePriority(role, least, greatest, DeferredRematchBelowVerification())));
  return stream;
}

}  // namespace cuda
}  // namespace cashash
