// Streams of the two GPU stages of a run. Matching and verification share
// the device; matching feeds the whole pipeline and its kernels are short,
// while one RANSAC block can run for thousands of trials. Matching streams
// therefore take the highest priority, so that its blocks are scheduled as
// soon as an SM frees up instead of queueing behind a chunk's verification.
//
// Priority cannot take back an SM that an E block already holds (255
// registers a thread: one block fills an SM for a pair's rounds). With
// CASHASH_GPU_MATCHING_RESERVED_SMS=N (an experiment, off by default)
// verification streams belong to a green context without N of the
// device's SMs, so those N are always free for matching; matching streams
// keep the whole device.
#pragma once

#include <cuda_runtime.h>

namespace cashash {
namespace cuda {

enum class StreamRole { kMatching, kVerification };

// A non-blocking stream with the role's priority on the current device.
cudaStream_t CreateStageStream(StreamRole role);

}  // namespace cuda
}  // namespace cashash
