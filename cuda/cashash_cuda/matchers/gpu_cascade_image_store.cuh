// The GPU cascade's images on the device: each image's descriptors, hash
// codes and bucket tables in one block of device memory (device_image.cuh),
// uploaded through pinned staging when the image is added and hashed with
// the other images added since, in one launch, before the next match. One
// job: what is on the device for which image. Internal to the GPU cascade
// matcher.
#pragma once

#include <cuda_runtime.h>

#include <memory>
#include <unordered_map>
#include <vector>

#include "cashash/base/types.h"
#include "cashash/matchers/feature_matcher.h"
#include "cashash/matching/cascade_hashing.h"
#include "cashash_cuda/matchers/gpu_memory_books.cuh"
#include "cashash_cuda/matching/brute_force_matcher.cuh"
#include "cashash_cuda/matching/device_image.cuh"
#include "cashash_cuda/utils/device_memory.cuh"

namespace cashash {
namespace cuda {

// One image as the cascade holds it.
struct GpuCascadeImage {
  // Shared with the exact matchers that hold the image (HoldForExact); null
  // for an image without features.
  std::shared_ptr<PooledDeviceBlock> memory;
  DeviceImageParts parts;
  uint32_t num_features = 0;
  // Its keypoints where it came with them (epipolar guides); may be null.
  std::shared_ptr<const Keypoints> keypoints;

  // The rows AddImage uploaded, in the brute-force kernels' layout.
  DeviceDescriptors descriptors() const { return DeviceDescriptors{parts.descriptors, static_cast<int>(num_features)}; }
};

class GpuCascadeImageStore {
 public:
  // Hashes with `options`' projections around `mean`; uploads and hashes on
  // `stream`; takes its blocks from `resources` and counts them in `books`
  // (both must outlive it). The device must be current.
  GpuCascadeImageStore(const SiftMatchingOptions& sift_options, const CasHashOptions& options,
                       const MeanDescriptor& mean, GpuResources* resources, GpuMemoryBooks* books,
                       cudaStream_t stream);
  GpuCascadeImageStore(const GpuCascadeImageStore&) = delete;
  GpuCascadeImageStore& operator=(const GpuCascadeImageStore&) = delete;

  // Uploads the image's rows (at most max_num_matches); replaces one of
  // the same id. Throws DeviceMemoryError past the budget.
  void Add(const MatcherImage& image);
  void Remove(image_t image_id);
  // Throws std::invalid_argument for an image not added.
  const GpuCascadeImage& Find(image_t image_id) const;
  // Hashes and buckets every image added since the last call, in one
  // launch; returns once they are ready.
  void HashPending();

 private:
  void UploadProjections(const CascadeProjections& projections, const MeanDescriptor& mean);

  const SiftMatchingOptions sift_options_;
  const CasHashOptions options_;
  GpuResources* resources_;
  GpuMemoryBooks* books_;
  cudaStream_t stream_;
  int rows_padded_ = 0;
  DeviceBuffer projections_t_;
  DeviceBuffer row_offsets_;
  std::unordered_map<image_t, GpuCascadeImage> images_;
  std::vector<image_t> pending_;
  PinnedUploadRing uploads_;
};

}  // namespace cuda
}  // namespace cashash
