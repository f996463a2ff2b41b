// The GPU Cascade Hashing backend, put together from parts with one job
// each: the images on the device (GpuCascadeImageStore: upload, hash,
// bucket), the matching of a chunk in batches on two streams
// (GpuCascadeBatches), the guides of guided pairs (GpuEpipolarGuides) and
// exact matching from the device descriptors (GpuExactMatching). They share
// the device's owner of memory (GpuResources) and the matcher's books of it
// (GpuMemoryBooks), so one budget bounds images and scratch together.
#include "cashash_cuda/matchers/gpu_cascade_feature_matcher.h"

#include <cuda_runtime.h>

#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "cashash_cuda/matchers/gpu_cascade_batches.cuh"
#include "cashash_cuda/matchers/gpu_cascade_image_store.cuh"
#include "cashash_cuda/matchers/gpu_epipolar_guides.cuh"
#include "cashash_cuda/matchers/gpu_exact_matching.cuh"
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#include "cashash_cuda/matching/cascade_hashing.cuh"
#include "cashash_cuda/matching/cascade_matcher.cuh"
#include "cashash_cuda/utils/cuda_check.cuh"

namespace cashash {
namespace cuda {
namespace {

std::string CheckGpuCascadeOptions(const CasHashOptions& options) {
  if (options.num_tables * options.bits_per_table > kMaxSignatureBits) {
    return "the GPU cascade matcher needs CasHash.num_tables * CasHash.bits_per_table <= " +
           std::to_string(kMaxSignatureBits) + ", got " + std::to_string(options.num_tables * options.bits_per_table);
  }
  if (options.num_tables > kMaxGpuTables) {
    return "the GPU cascade matcher needs CasHash.num_tables <= " + std::to_string(kMaxGpuTables) + ", got " +
           std::to_string(options.num_tables);
  }
  if (options.top_k > kMaxGpuTopK) {
    return "the GPU cascade matcher needs CasHash.top_k <= " + std::to_string(kMaxGpuTopK) + ", got " +
           std::to_string(options.top_k);
  }
  return "";
}

// Checks the options and the device, and makes it current, before any part
// is built.
int CheckedDevice(const SiftMatchingOptions& sift_options, const CasHashOptions& options, int device) {
  std::string error = sift_options.Check();
  if (error.empty()) error = options.Check();
  if (error.empty()) error = options.CheckDecided();
  if (error.empty()) error = CheckGpuCascadeOptions(options);
  if (!error.empty()) throw std::invalid_argument(error);
  std::string reason;
  if (!CudaDeviceUsable(device, &reason)) throw std::runtime_error(reason);
  CUDA_CHECK(cudaSetDevice(device));
  return device;
}

MatcherTraits CascadeTraits() {
  MatcherTraits traits;
  traits.name = "gpu-cascade";
  traits.epipolar_guidance = true;
  return traits;
}

class GpuCascadeMatcher : public MatchingBackend {
 public:
  GpuCascadeMatcher(const SiftMatchingOptions& sift_options, const CasHashOptions& options,
                    const MeanDescriptor& mean, const GpuMatcherConfig& config)
      : MatchingBackend(CascadeTraits()),
        device_(CheckedDevice(sift_options, options, config.gpu_index)),
        resources_(config.resources ? config.resources
                                    : std::make_shared<GpuResources>(config.gpu_index, config.memory_budget_bytes)),
        books_(CheckedBudget(resources_, device_)),
        batches_(sift_options, options, device_, config.cascade_kernel == GpuCascadeKernel::kBucketTiles,
                 resources_.get(), &books_),
        store_(sift_options, options, mean, resources_.get(), &books_, batches_.first_stream()),
        exact_(device_, resources_, batches_.first_stream(), ToMatchThresholds(sift_options)),
        guides_(resources_.get(), &books_) {}
  // The parts give their memory back to this device.
  ~GpuCascadeMatcher() override { cudaSetDevice(device_); }

  void AddImage(const Image& image) override {
    CUDA_CHECK(cudaSetDevice(device_));
    store_.Add(image);
  }
  using FeatureMatcher::AddImage;

  void RemoveImage(image_t image_id) override { store_.Remove(image_id); }

  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& guides = {}) override {
    CheckGuides(pairs, guides);
    CUDA_CHECK(cudaSetDevice(device_));
    store_.HashPending();
    std::vector<FeatureMatches> results(pairs.size());
    // Tasks in pair order, so that neighbouring warps share the target image.
    std::vector<PairTask> tasks;
    std::vector<size_t> pair_of_task;
    for (size_t i = 0; i < pairs.size(); ++i) {
      const GpuCascadeImage& a = store_.Find(pairs[i].first);
      const GpuCascadeImage& b = store_.Find(pairs[i].second);
      if (a.num_features == 0 || b.num_features == 0) continue;
      PairTask task;
      task.a = a.parts.View();
      task.b = b.parts.View();
      tasks.push_back(task);
      pair_of_task.push_back(i);
    }
    if (!guides.empty()) guides_.Prepare(store_, pairs, guides, pair_of_task, batches_.first_stream());
    batches_.Match(tasks, pair_of_task, guides.empty() ? nullptr : &guides_, &results);
    return results;
  }

  // Exact matches from the descriptors each image keeps on the device: no
  // second upload, on the first batch slot's stream, idle between calls.
  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override {
    return exact_.Match(store_, pairs);
  }

  // The pairs' device descriptors, lent with their blocks: the deferred
  // rematch then reads what AddImage uploaded instead of uploading it again
  // beside the next chunk's images.
  std::unique_ptr<ExactMatcher> HoldForExact(const std::vector<ImagePair>& pairs) override {
    return exact_.Hold(store_, pairs);
  }

 private:
  static size_t CheckedBudget(const std::shared_ptr<GpuResources>& resources, int device) {
    if (resources->device() != device) throw std::invalid_argument("GPU cascade matcher: resources of another device");
    return resources->budget_bytes();
  }

  const int device_;
  // First in, last out: every part's buffers and blocks return to it.
  std::shared_ptr<GpuResources> resources_;
  GpuMemoryBooks books_;
  // Before the parts that use its streams, so that they go first.
  GpuCascadeBatches batches_;
  GpuCascadeImageStore store_;
  GpuExactMatching exact_;
  GpuEpipolarGuides guides_;
};

}  // namespace

std::unique_ptr<MatchingBackend> CreateGpuCascadeMatcher(const SiftMatchingOptions& sift_options,
                                                         const CasHashOptions& cashash_options,
                                                         const MeanDescriptor& mean, const GpuMatcherConfig& config) {
  return std::make_unique<GpuCascadeMatcher>(sift_options, cashash_options, mean, config);
}

}  // namespace cuda
}  // namespace cashash
