// Entry points of the GPU backend (cashash_cuda/matchers/gpu_feature_matcher.h): the
// device queries and the factory, plus the brute-force backend that keeps
// descriptors on the device and calls the brute-force kernels.
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
#include "cashash_cuda/matchers/gpu_exact_matching.cuh"
#include "cashash_cuda/matchers/gpu_memory_books.cuh"
#include "cashash_cuda/matching/cascade_matcher.cuh"
#include "cashash_cuda/utils/architecture_support.h"
#include "cashash_cuda/utils/device_memory.cuh"
#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/stream_priority.cuh"

namespace cashash {
namespace cuda {
namespace {

MatcherTraits BruteForceTraits() {
  MatcherTraits traits;
  traits.name = "gpu-bruteforce";
  return traits;
}

// One image's descriptors on the device.
struct BruteForceImage {
  std::shared_ptr<PooledDeviceBlock> memory;  // null without features; shared with held exact matchers
  int rows = 0;
  DeviceDescriptors descriptors() const {
    return DeviceDescriptors{memory ? memory->as<uint8_t>() : nullptr, rows};
  }
};

// Held images of the brute-force matcher, matched on any thread with
// kernels of their own stream (made per call: this path only serves tests
// and callers outside a run, which defers only the cascade's rematch).
class HeldBruteForceImages : public ExactMatcher {
 public:
  HeldBruteForceImages(int device, std::shared_ptr<GpuResources> resources, const MatchThresholds& thresholds,
                       std::unordered_map<image_t, BruteForceImage> images)
      : device_(device), resources_(std::move(resources)), thresholds_(thresholds), images_(std::move(images)) {}
  ~HeldBruteForceImages() override {
    cudaSetDevice(device_);
    images_.clear();
  }
  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override {
    std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>> device_pairs;
    for (const ImagePair& pair : pairs) device_pairs.emplace_back(Find(pair.first), Find(pair.second));
    ExactKernels kernels(device_, resources_);
    return MatchPairsInBatches(kernels.kernels(), device_pairs, thresholds_, kernels.scratch_bytes());
  }

 private:
  DeviceDescriptors Find(image_t image_id) const {
    const auto it = images_.find(image_id);
    if (it == images_.end()) {
      throw std::invalid_argument("held GPU images: image " + std::to_string(image_id) + " was not held");
    }
    return it->second.descriptors();
  }
  const int device_;
  std::shared_ptr<GpuResources> resources_;  // outlives images_
  const MatchThresholds thresholds_;
  std::unordered_map<image_t, BruteForceImage> images_;
};

class GpuBruteForceMatcher : public MatchingBackend {
 public:
  GpuBruteForceMatcher(const SiftMatchingOptions& sift_options, const GpuMatcherConfig& config)
      : MatchingBackend(BruteForceTraits()),
        sift_options_(sift_options),
        device_(config.gpu_index),
        resources_(config.resources ? config.resources
                                    : std::make_shared<GpuResources>(config.gpu_index, config.memory_budget_bytes)),
        books_(resources_->budget_bytes()) {
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

  void AddImage(const Image& added) override {
    CUDA_CHECK(cudaSetDevice(device_));
    RemoveImage(added.id);
    const FeatureDescriptors& descriptors = *added.descriptors;
    const size_t n = std::min(descriptors.rows(), static_cast<size_t>(sift_options_.max_num_matches));
    BruteForceImage image;
    image.rows = static_cast<int>(n);
    if (n > 0) {
      const size_t bytes = n * kDescriptorDim;
      books_.Reserve(bytes, "image " + std::to_string(added.id));
      try {
        // From the pool, through pinned staging, on the stream the kernels
        // use: no cudaMalloc, no wait (as the cascade's images).
        image.memory = std::make_shared<PooledDeviceBlock>(resources_.get(), bytes, "image descriptors");
      } catch (...) {
        books_.Release(bytes);
        throw;
      }
      uploads_.Upload(descriptors.data.data(), bytes, image.memory->as<uint8_t>(), stream_);
    }
    images_.emplace(added.id, std::move(image));
  }
  using FeatureMatcher::AddImage;

  void RemoveImage(image_t image_id) override {
    const auto it = images_.find(image_id);
    if (it == images_.end()) return;
    if (it->second.memory) books_.Release(it->second.memory->bytes());
    images_.erase(it);
  }

  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& guides = {}) override {
    CheckGuides(pairs, guides);
    CUDA_CHECK(cudaSetDevice(device_));
    std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>> device_pairs;
    device_pairs.reserve(pairs.size());
    for (const ImagePair& pair : pairs) {
      device_pairs.emplace_back(Find(pair.first).descriptors(), Find(pair.second).descriptors());
    }
    return MatchPairsInBatches(kernels_.get(), device_pairs, ToMatchThresholds(sift_options_),
                               resources_->ScratchBytes());
  }

  // Brute force is exact already.
  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override { return Match(pairs); }

  std::unique_ptr<ExactMatcher> HoldForExact(const std::vector<ImagePair>& pairs) override {
    std::unordered_map<image_t, BruteForceImage> held;
    for (const ImagePair& pair : pairs) {
      held.emplace(pair.first, Find(pair.first));
      held.emplace(pair.second, Find(pair.second));
    }
    return std::make_unique<HeldBruteForceImages>(device_, resources_, ToMatchThresholds(sift_options_),
                                                  std::move(held));
  }

 private:
  const BruteForceImage& Find(image_t image_id) const {
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
  GpuMemoryBooks books_;
  cudaStream_t stream_ = nullptr;
  std::unique_ptr<BruteForceKernels> kernels_;
  std::unordered_map<image_t, BruteForceImage> images_;
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

std::unique_ptr<MatchingBackend> CreateGpuFeatureMatcher(const SiftMatchingOptions& sift_options,
                                                         const CasHashOptions& cashash_options,
                                                         const MeanDescriptor& mean, const GpuMatcherConfig& config) {
  // Auto, tau and the rematch threshold chosen for the run are decided by
  // the run before any matcher is built (CasHashOptions::CheckDecided).
  const std::string undecided = cashash_options.CheckDecided();
  if (!undecided.empty()) throw std::invalid_argument(undecided);
  if (cashash_options.matcher == MatcherType::kBruteForce) {
    return std::make_unique<GpuBruteForceMatcher>(sift_options, config);
  }
  // Tables still at 0 (chosen per run, table_shape.h): the shape of 8,192
  // features, as the CPU backend.
  return CreateGpuCascadeMatcher(sift_options, ResolveTableShape(cashash_options, 0), mean, config);
}

std::unique_ptr<MatchingBackend> CreateGpuFeatureMatcher(const SiftMatchingOptions& sift_options,
                                                         const CasHashOptions& cashash_options,
                                                         const MeanDescriptor& mean, int gpu_index) {
  GpuMatcherConfig config;
  config.gpu_index = gpu_index;
  return CreateGpuFeatureMatcher(sift_options, cashash_options, mean, config);
}

}  // namespace cuda
}  // namespace cashash
