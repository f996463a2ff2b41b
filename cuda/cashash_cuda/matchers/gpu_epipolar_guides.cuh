// The epipolar guides of one guided Match call of the GPU cascade, on the
// device: every guided image's keypoint pixels once (float2, from the
// keypoints the image was added with), and per task F with where its two
// images' pixels start. One job: guidance in the kernels' layout. Internal
// to the GPU cascade matcher.
#pragma once

#include <cuda_runtime.h>

#include <vector>

#include "cashash/matchers/feature_matcher.h"
#include "cashash_cuda/matchers/gpu_cascade_image_store.cuh"
#include "cashash_cuda/matchers/gpu_memory_books.cuh"
#include "cashash_cuda/matching/cascade_matcher.cuh"

namespace cashash {
namespace cuda {

class GpuEpipolarGuides {
 public:
  // Pixels from `resources`, counted in `books` (both outlive it).
  GpuEpipolarGuides(GpuResources* resources, GpuMemoryBooks* books) : resources_(resources), books_(books) {}

  // The guides of the tasks (task t matches pairs[pair_of_task[t]] with
  // guides[pair_of_task[t]]), the pixels uploaded on `stream` and waited
  // for. Throws std::invalid_argument where a guided image has no keypoints
  // for its features or the guides' max_distance differ (one band per call).
  void Prepare(const GpuCascadeImageStore& store, const std::vector<ImagePair>& pairs,
               const std::vector<EpipolarGuide>& guides, const std::vector<size_t>& pair_of_task, cudaStream_t stream);

  const std::vector<EpipolarGuideDevice>& of_tasks() const { return of_tasks_; }
  const float2* points() const { return points_.as<float2>(); }
  double max_distance() const { return max_distance_; }

 private:
  GpuResources* resources_;
  GpuMemoryBooks* books_;
  std::vector<EpipolarGuideDevice> of_tasks_;
  DeviceBuffer points_;
  double max_distance_ = 0;
};

}  // namespace cuda
}  // namespace cashash
