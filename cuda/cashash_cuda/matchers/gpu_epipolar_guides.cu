#include "cashash_cuda/matchers/gpu_epipolar_guides.cuh"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include "cashash_cuda/utils/cuda_check.cuh"

namespace cashash {
namespace cuda {

void GpuEpipolarGuides::Prepare(const GpuCascadeImageStore& store, const std::vector<ImagePair>& pairs,
                                const std::vector<EpipolarGuide>& guides, const std::vector<size_t>& pair_of_task,
                                cudaStream_t stream) {
  // Each guided image's pixels once: where they start in points_.
  std::unordered_map<image_t, uint32_t> offset_of;
  std::vector<const GpuCascadeImage*> placed;
  size_t total = 0;  // float2 entries
  auto place = [&](image_t id, size_t pair) -> uint32_t {
    const auto it = offset_of.find(id);
    if (it != offset_of.end()) return it->second;
    const GpuCascadeImage& image = store.Find(id);
    if (!image.keypoints || image.keypoints->size() < image.num_features) {
      throw std::invalid_argument("GPU guided matching: pair " + std::to_string(pair) +
                                  " lacks keypoint positions for its features");
    }
    if (total + image.num_features >= (size_t{1} << 32)) {
      throw std::runtime_error("GPU guided matching: too many keypoints in one call");
    }
    const uint32_t offset = static_cast<uint32_t>(total);
    offset_of.emplace(id, offset);
    placed.push_back(&image);
    total += image.num_features;
    return offset;
  };
  max_distance_ = guides.empty() ? 0 : guides.front().max_distance;
  of_tasks_.resize(pair_of_task.size());
  for (size_t t = 0; t < pair_of_task.size(); ++t) {
    const size_t p = pair_of_task[t];
    if (guides[p].max_distance != max_distance_) {
      throw std::invalid_argument("GPU guided matching: one band half-width per call");
    }
    std::copy(guides[p].F.begin(), guides[p].F.end(), of_tasks_[t].F);
    of_tasks_[t].points_a = place(pairs[p].first, p);
    of_tasks_[t].points_b = place(pairs[p].second, p);
  }
  const size_t bytes = std::max<size_t>(total, 1) * sizeof(float2);
  if (points_.bytes() < bytes) {
    books_->Release(points_.bytes());
    points_.Release();
    books_->Reserve(bytes, "keypoint positions");
    points_.Allocate(resources_, bytes, "keypoint positions");
  }
  std::vector<float2> staged;
  staged.reserve(total);
  for (const GpuCascadeImage* image : placed) {
    const Keypoints& keypoints = *image->keypoints;
    for (uint32_t i = 0; i < image->num_features; ++i) staged.push_back(make_float2(keypoints[i].x, keypoints[i].y));
  }
  if (total > 0) {
    CUDA_CHECK(cudaMemcpyAsync(points_.as<float2>(), staged.data(), total * sizeof(float2), cudaMemcpyHostToDevice,
                               stream));
    CUDA_CHECK(cudaStreamSynchronize(stream));
  }
}

}  // namespace cuda
}  // namespace cashash
