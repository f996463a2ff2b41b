// What every GPU test file needs: skip (with the reason) where no usable
// CUDA device exists, so that the suite passes on machines without a GPU.
#pragma once

#include <string>

#include <gtest/gtest.h>

#include "cashash_cuda/matchers/gpu_feature_matcher.h"

#define SKIP_WITHOUT_CUDA_DEVICE()                                                            \
  do {                                                                                        \
    std::string cuda_skip_reason;                                                             \
    if (::cashash::cuda::NumCudaDevices() == 0 ||                                             \
        !::cashash::cuda::CudaDeviceUsable(0, &cuda_skip_reason)) {                           \
      GTEST_SKIP() << "no CUDA device: " << (cuda_skip_reason.empty() ? "none found" : cuda_skip_reason); \
    }                                                                                         \
  } while (0)
