#include "cashash_cuda/utils/stream_priority.cuh"

#include <cuda.h>
#include <cudaTypedefs.h>

#include <cstdlib>
#include <iostream>
#include <map>
#include <mutex>

#include "cashash_cuda/utils/cuda_check.cuh"

namespace cashash {
namespace cuda {
namespace {

// Driver entry points through the runtime, so that nothing links libcuda
// (binaries must load on machines without a driver, where tests skip).
template <typename Function>
Function DriverFunction(const char* name, unsigned int version) {
  void* function = nullptr;
  cudaDriverEntryPointQueryResult status = cudaDriverEntryPointSymbolNotFound;
  if (cudaGetDriverEntryPointByVersion(name, &function, version, cudaEnableDefault, &status) != cudaSuccess ||
      status != cudaDriverEntryPointSuccess) {
    return nullptr;
  }
  return reinterpret_cast<Function>(function);
}

int ReservedSms() {
  const char* value = std::getenv("CASHASH_GPU_MATCHING_RESERVED_SMS");
  return value != nullptr ? std::atoi(value) : 0;
}

// The green context of verification on `device`: every SM but `reserved`
// (rounded by the driver to its partition granularity). Null when the
// driver cannot make one; the caller then uses an ordinary stream.
CUgreenCtx VerificationContext(int device, int reserved) {
  static std::mutex mutex;
  static std::map<int, CUgreenCtx> contexts;
  std::lock_guard<std::mutex> lock(mutex);
  const auto found = contexts.find(device);
  if (found != contexts.end()) return found->second;
  CUgreenCtx context = nullptr;
  auto get_device = DriverFunction<PFN_cuDeviceGet_v2000>("cuDeviceGet", 2000);
  auto get_resource = DriverFunction<PFN_cuDeviceGetDevResource_v12040>("cuDeviceGetDevResource", 12040);
  auto split = DriverFunction<PFN_cuDevSmResourceSplitByCount_v12040>("cuDevSmResourceSplitByCount", 12040);
  auto describe = DriverFunction<PFN_cuDevResourceGenerateDesc_v12040>("cuDevResourceGenerateDesc", 12040);
  auto create = DriverFunction<PFN_cuGreenCtxCreate_v12040>("cuGreenCtxCreate", 12040);
  CUdevice handle = 0;
  CUdevResource all{}, group{}, rest{};
  CUdevResourceDesc desc = nullptr;
  unsigned int groups = 1;
  if (get_device && get_resource && split && describe && create && get_device(&handle, device) == CUDA_SUCCESS &&
      get_resource(handle, &all, CU_DEV_RESOURCE_TYPE_SM) == CUDA_SUCCESS && reserved > 0 &&
      static_cast<unsigned int>(reserved) < all.sm.smCount &&
      split(&group, &groups, &all, &rest, 0, all.sm.smCount - static_cast<unsigned int>(reserved)) ==
          CUDA_SUCCESS &&
      groups == 1 && describe(&desc, &group, 1) == CUDA_SUCCESS &&
      create(&context, desc, handle, CU_GREEN_CTX_DEFAULT_STREAM) == CUDA_SUCCESS) {
    std::cerr << "GPU " << device << ": verification on " << group.sm.smCount << " of " << all.sm.smCount
              << " SMs (CASHASH_GPU_MATCHING_RESERVED_SMS=" << reserved << ")" << std::endl;
  } else {
    context = nullptr;
    std::cerr << "WARNING: GPU " << device << ": CASHASH_GPU_MATCHING_RESERVED_SMS=" << reserved
              << " not applied (no green context); verification shares every SM" << std::endl;
  }
  contexts.emplace(device, context);
  return context;
}

}  // namespace

cudaStream_t CreateStageStream(StreamRole role) {
  int least = 0, greatest = 0;  // numerically: least >= greatest
  CUDA_CHECK(cudaDeviceGetStreamPriorityRange(&least, &greatest));
  const int priority = role == StreamRole::kMatching ? greatest : least;
  const int reserved = role == StreamRole::kVerification ? ReservedSms() : 0;
  if (reserved > 0) {
    int device = 0;
    CUDA_CHECK(cudaGetDevice(&device));
    auto stream_create = DriverFunction<PFN_cuGreenCtxStreamCreate_v12050>("cuGreenCtxStreamCreate", 12050);
    const CUgreenCtx context = VerificationContext(device, reserved);
    CUstream stream = nullptr;
    if (context != nullptr && stream_create != nullptr &&
        stream_create(&stream, context, CU_STREAM_NON_BLOCKING, priority) == CUDA_SUCCESS) {
      return reinterpret_cast<cudaStream_t>(stream);
    }
  }
  cudaStream_t stream = nullptr;
  CUDA_CHECK(cudaStreamCreateWithPriority(&stream, cudaStreamNonBlocking, priority));
  return stream;
}

}  // namespace cuda
}  // namespace cashash
