// Streams of the two GPU stages of a run. Matching and verification share
// the device; matching feeds the whole pipeline and its kernels are short,
// while one RANSAC block can run for thousands of trials. Matching streams
// therefore take the highest priority, so that its blocks are scheduled as
// soon as an SM frees up instead of queueing behind a chunk's verification.
#pragma once

#include <cuda_runtime.h>

#include "cashash_cuda/utils/cuda_check.cuh"

namespace cashash {
namespace cuda {

enum class StreamRole { kMatching, kVerification };

// A non-blocking stream with the role's priority on the current device.
inline cudaStream_t CreateStageStream(StreamRole role) {
  int least = 0, greatest = 0;  // numerically: least >= greatest
  CUDA_CHECK(cudaDeviceGetStreamPriorityRange(&least, &greatest));
  cudaStream_t stream = nullptr;
  CUDA_CHECK(cudaStreamCreateWithPriority(&stream, cudaStreamNonBlocking,
                                          role == StreamRole::kMatching ? greatest : least));
  return stream;
}

}  // namespace cuda
}  // namespace cashash
