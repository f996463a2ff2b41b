#include "cashash_cuda/matchers/gpu_exact_matching.cuh"

#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>

#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/stream_priority.cuh"

namespace cashash {
namespace cuda {
namespace {

// One held image: its block (null without features) and its descriptors.
struct HeldImage {
  std::shared_ptr<PooledDeviceBlock> memory;
  DeviceDescriptors descriptors;
};

// Exact matches of held images, on any thread, with pooled kernels.
class HeldGpuImages : public ExactMatcher {
 public:
  HeldGpuImages(int device, std::shared_ptr<GpuResources> resources, std::shared_ptr<ExactKernelsPool> kernels,
                const MatchThresholds& thresholds, std::unordered_map<image_t, HeldImage> images)
      : device_(device),
        resources_(std::move(resources)),
        kernels_(std::move(kernels)),
        thresholds_(thresholds),
        images_(std::move(images)) {}
  ~HeldGpuImages() override {
    cudaSetDevice(device_);  // the blocks go back to a pool of this device
    images_.clear();
  }

  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override {
    std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>> device_pairs;
    device_pairs.reserve(pairs.size());
    for (const ImagePair& pair : pairs) device_pairs.emplace_back(Find(pair.first), Find(pair.second));
    CUDA_CHECK(cudaSetDevice(device_));
    std::unique_ptr<ExactKernels> lease = kernels_->Acquire();
    std::vector<FeatureMatches> matches =
        MatchPairsInBatches(lease->kernels(), device_pairs, thresholds_, lease->scratch_bytes());
    kernels_->Release(std::move(lease));
    return matches;
  }

 private:
  DeviceDescriptors Find(image_t image_id) const {
    const auto it = images_.find(image_id);
    if (it == images_.end()) {
      throw std::invalid_argument("held GPU images: image " + std::to_string(image_id) + " was not held");
    }
    return it->second.descriptors;
  }

  const int device_;
  std::shared_ptr<GpuResources> resources_;  // first in, last out: outlives images_
  std::shared_ptr<ExactKernelsPool> kernels_;
  const MatchThresholds thresholds_;
  std::unordered_map<image_t, HeldImage> images_;
};

}  // namespace

ExactKernels::ExactKernels(int device, std::shared_ptr<GpuResources> resources)
    : device_(device), resources_(std::move(resources)) {
  CUDA_CHECK(cudaSetDevice(device));
  stream_ = CreateStageStream(StreamRole::kMatching);
  try {
    kernels_ = std::make_unique<BruteForceKernels>(stream_, resources_.get());
  } catch (...) {
    cudaStreamDestroy(stream_);
    throw;
  }
}

ExactKernels::~ExactKernels() {
  cudaSetDevice(device_);
  kernels_.reset();
  cudaStreamDestroy(stream_);
}

GpuExactMatching::GpuExactMatching(int device, std::shared_ptr<GpuResources> resources, cudaStream_t stream,
                                   const MatchThresholds& thresholds)
    : device_(device), resources_(std::move(resources)), stream_(stream), thresholds_(thresholds) {}

std::vector<FeatureMatches> GpuExactMatching::Match(const GpuCascadeImageStore& store,
                                                    const std::vector<ImagePair>& pairs) {
  CUDA_CHECK(cudaSetDevice(device_));
  if (!kernels_) kernels_ = std::make_unique<BruteForceKernels>(stream_, resources_.get());
  std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>> device_pairs;
  device_pairs.reserve(pairs.size());
  for (const ImagePair& pair : pairs) {
    device_pairs.emplace_back(store.Find(pair.first).descriptors(), store.Find(pair.second).descriptors());
  }
  return MatchPairsInBatches(kernels_.get(), device_pairs, thresholds_, resources_->ScratchBytes());
}

std::unique_ptr<ExactMatcher> GpuExactMatching::Hold(const GpuCascadeImageStore& store,
                                                     const std::vector<ImagePair>& pairs) {
  if (!held_kernels_) {
    held_kernels_ = std::make_shared<ExactKernelsPool>(
        [device = device_, resources = resources_] { return std::make_unique<ExactKernels>(device, resources); });
  }
  std::unordered_map<image_t, HeldImage> images;
  for (const ImagePair& pair : pairs) {
    for (const image_t id : {pair.first, pair.second}) {
      if (images.count(id)) continue;
      const GpuCascadeImage& image = store.Find(id);
      images.emplace(id, HeldImage{image.memory, image.descriptors()});
    }
  }
  return std::make_unique<HeldGpuImages>(device_, resources_, held_kernels_, thresholds_, std::move(images));
}

}  // namespace cuda
}  // namespace cashash
