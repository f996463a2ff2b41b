// Entry points of the GPU backend (cashash_cuda/matchers/gpu_feature_matcher.h): the
// device queries and the factory, plus the brute-force FeatureMatcher that
// keeps descriptors on the device and calls the brute-force kernels.
#include "cashash_cuda/matchers/gpu_feature_matcher.h"

#include <cuda_runtime.h>

#include <algorithm>
#include <memory>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "cashash/base/device_memory_error.h"
#include "cashash/matching/table_shape.h"
#include "cashash_cuda/matching/brute_force_matcher.cuh"
#include "cashash_cuda/matchers/gpu_cascade_feature_matcher.h"
#include "cashash_cuda/matching/cascade_matcher.cuh"
#include "cashash_cuda/utils/architecture_support.h"
#include "cashash_cuda/utils/device_memory.cuh"
#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/stream_priority.cuh"

namespace cashash {
namespace cuda {
namespace {

class GpuBruteForceMatcher : public FeatureMatcher {
 public:
  GpuBruteForceMatcher(const SiftMatchingOptions& sift_options, const GpuMatcherConfig& config)
      : sift_options_(sift_options),
        device_(config.gpu_index),
        resources_(config.resources ? config.resources
                                    : std::make_shared<GpuResources>(config.gpu_index, config.memory_budget_bytes)),
        budget_(MemoryBudget(resources_->budget_bytes())) {
    const std::string error = sift_options.Check();
    if (!error.empty()) throw std::invalid_argument(error);
    std::string reason;
    if (!CudaDeviceUsable(device_, &reason)) throw std::runtime_error(reason);
    CUDA_CHECK(cudaSetDevice(device_));
    stream_ = CreateStageStream(StreamRole::kMatching);
    kernels_ = std::make_unique<BruteForceKernels>(stream_, resources_.get());
  }
  ~GpuBruteForceMatcher() override {
    cudaSetDevice(device_);
    if (stream_ != nullptr) cudaStreamSynchronize(stream_);
    kernels_.reset();
    images_.clear();
    if (stream_ != nullptr) cudaStreamDestroy(stream_);
  }

  void AddImage(image_t image_id, const FeatureDescriptors& descriptors) override {
    CUDA_CHECK(cudaSetDevice(device_));
    RemoveImage(image_id);
    const size_t n = std::min(descriptors.rows(), static_cast<size_t>(sift_options_.max_num_matches));
    Image image;
    image.rows = static_cast<int>(n);
    if (n > 0) {
      const size_t bytes = n * kDescriptorDim;
      if (bytes > budget_ || used_ > budget_ - bytes) {
        throw DeviceMemoryError("GPU memory budget exceeded by image " + std::to_string(image_id) + ": it needs " +
                                 MiB(bytes) + ", " + MiB(used_) + " of " + MiB(budget_) + " are in use");
      }
      // From the pool, through pinned staging, on the stream the kernels
      // use: no cudaMalloc, no wait (as the cascade's images).
      image.memory = PooledDeviceBlock(resources_.get(), bytes, "image descriptors");
      uploads_.Upload(descriptors.data.data(), bytes, image.memory.as<uint8_t>(), stream_);
      used_ += bytes;
    }
    images_.emplace(image_id, std::move(image));
  }

  void RemoveImage(image_t image_id) override {
    const auto it = images_.find(image_id);
    if (it == images_.end()) return;
    used_ -= it->second.memory.bytes();
    images_.erase(it);
  }

  std::vector<FeatureMatches> MatchPairs(const std::vector<ImagePair>& pairs) override {
    CUDA_CHECK(cudaSetDevice(device_));
    std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>> device_pairs;
    device_pairs.reserve(pairs.size());
    for (const ImagePair& pair : pairs) {
      const Image& a = Find(pair.first);
      const Image& b = Find(pair.second);
      device_pairs.emplace_back(DeviceDescriptors{a.memory.as<uint8_t>(), a.rows},
                                DeviceDescriptors{b.memory.as<uint8_t>(), b.rows});
    }
    return MatchPairsInBatches(kernels_.get(), device_pairs, ToMatchThresholds(sift_options_),
                               resources_->ScratchBytes());
  }

  bool SupportsExactMatching() const override { return true; }
  std::vector<FeatureMatches> MatchPairsExact(const std::vector<ImagePair>& pairs) override {
    return MatchPairs(pairs);
  }

  std::string Name() const override { return "gpu-bruteforce"; }

 private:
  struct Image {
    PooledDeviceBlock memory;
    int rows = 0;
  };
  const Image& Find(image_t image_id) const {
    const auto it = images_.find(image_id);
    if (it == images_.end()) {
      throw std::invalid_argument("GPU matcher: image " + std::to_string(image_id) + " was not added");
    }
    return it->second;
  }

  const SiftMatchingOptions sift_options_;
  const int device_;
  // First in, last out: the images, kernels and staging return to it.
  std::shared_ptr<GpuResources> resources_;
  const size_t budget_;
  size_t used_ = 0;
  cudaStream_t stream_ = nullptr;
  std::unique_ptr<BruteForceKernels> kernels_;
  std::unordered_map<image_t, Image> images_;
  PinnedUploadRing uploads_{resources_.get()};
};

// A kernel compiled like every other of the backend: whether the driver can
// load it tells whether the binary holds code (SASS or PTX) for the device.
__global__ void KernelImageProbe() {}

// The device's name, or "unknown" when the driver does not say.
std::string DeviceName(int gpu_index) {
  cudaDeviceProp properties{};
  if (cudaGetDeviceProperties(&properties, gpu_index) != cudaSuccess) {
    (void)cudaGetLastError();
    return "unknown";
  }
  return properties.name;
}

}  // namespace

int NumCudaDevices() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess) {
    (void)cudaGetLastError();
    return 0;
  }
  return count;
}

bool CudaDeviceUsable(int gpu_index, std::string* reason) {
  auto fail = [reason](const std::string& why) {
    if (reason != nullptr) *reason = why;
    return false;
  };
  const int count = NumCudaDevices();
  if (count == 0) return fail("no CUDA device (or no driver) found");
  if (gpu_index < 0 || gpu_index >= count) {
    return fail("CUDA device " + std::to_string(gpu_index) + " does not exist (" + std::to_string(count) +
                " found)");
  }
  if (cudaSetDevice(gpu_index) != cudaSuccess) {
    const cudaError_t e = cudaGetLastError();
    return fail("cannot use CUDA device " + std::to_string(gpu_index) + ": " + cudaGetErrorString(e));
  }
  // The device must find code it can run among the architectures the binary
  // was built for (architecture_support.h); the probe asks the driver too.
  int major = 0, minor = 0;
  (void)cudaDeviceGetAttribute(&major, cudaDevAttrComputeCapabilityMajor, gpu_index);
  (void)cudaDeviceGetAttribute(&minor, cudaDevAttrComputeCapabilityMinor, gpu_index);
  cudaFuncAttributes probe{};
  const cudaError_t loaded = cudaFuncGetAttributes(&probe, KernelImageProbe);
  (void)cudaGetLastError();
  if (!CanRunOnDevice(CompiledCudaArchitectures(), major, minor) || loaded == cudaErrorNoKernelImageForDevice ||
      loaded == cudaErrorInvalidDeviceFunction) {
    return fail(UnservableDeviceMessage(gpu_index, DeviceName(gpu_index), major, minor, CompiledCudaArchitectures()));
  }
  if (loaded != cudaSuccess) {
    return fail("CUDA device " + std::to_string(gpu_index) + " cannot load the GPU code: " +
                cudaGetErrorString(loaded));
  }
  try {
    (void)CascadeMatchGridSize(gpu_index);
  } catch (const std::exception& e) {
    (void)cudaGetLastError();
    return fail("CUDA device " + std::to_string(gpu_index) + " cannot run the kernels: " + e.what());
  }
  return true;
}

std::unique_ptr<FeatureMatcher> CreateGpuFeatureMatcher(const SiftMatchingOptions& sift_options,
                                                        const CasHashOptions& cashash_options,
                                                        const MeanDescriptor& mean, const GpuMatcherConfig& config) {
  // Auto is decided from the run's data before any matcher is built
  // (ChooseAutoMatcher, cashash/matching/matcher_choice.h).
  if (cashash_options.matcher == MatcherType::kAuto) {
    throw std::invalid_argument("CasHash.matcher auto must be resolved (ChooseAutoMatcher) before a matcher is built");
  }
  if (cashash_options.matcher == MatcherType::kBruteForce) {
    return std::make_unique<GpuBruteForceMatcher>(sift_options, config);
  }
  // Tables still at 0 (chosen per run, table_shape.h): the shape of 8,192
  // features, as the CPU backend.
  return CreateGpuCascadeMatcher(sift_options, ResolveTableShape(cashash_options, 0), mean, config);
}

std::unique_ptr<FeatureMatcher> CreateGpuFeatureMatcher(const SiftMatchingOptions& sift_options,
                                                        const CasHashOptions& cashash_options,
                                                        const MeanDescriptor& mean, int gpu_index) {
  GpuMatcherConfig config;
  config.gpu_index = gpu_index;
  return CreateGpuFeatureMatcher(sift_options, cashash_options, mean, config);
}

}  // namespace cuda
}  // namespace cashash
