#include "cashash_cuda/matchers/gpu_cascade_image_store.cuh"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>

#include "cashash_cuda/matching/cascade_hashing.cuh"
#include "cashash_cuda/matching/cascade_matcher.cuh"
#include "cashash_cuda/utils/cuda_check.cuh"

namespace cashash {
namespace cuda {

GpuCascadeImageStore::GpuCascadeImageStore(const SiftMatchingOptions& sift_options, const CasHashOptions& options,
                                           const MeanDescriptor& mean, GpuResources* resources,
                                           GpuMemoryBooks* books, cudaStream_t stream)
    : sift_options_(sift_options),
      options_(options),
      resources_(resources),
      books_(books),
      stream_(stream),
      uploads_(resources) {
  UploadProjections(GenerateCascadeProjections(options_), mean);
}

void GpuCascadeImageStore::Add(const MatcherImage& added) {
  Remove(added.id);
  const FeatureDescriptors& descriptors = *added.descriptors;
  const size_t n = std::min(descriptors.rows(), static_cast<size_t>(sift_options_.max_num_matches));
  if (n >= kMaxGpuFeatures) {
    throw std::runtime_error("image " + std::to_string(added.id) + " has " + std::to_string(n) +
                             " features; the GPU matcher handles at most " + std::to_string(kMaxGpuFeatures - 1) +
                             " per image");
  }
  GpuCascadeImage image;
  image.num_features = static_cast<uint32_t>(n);
  image.keypoints = added.keypoints;
  if (n > 0) {
    const DeviceImageLayout layout(n, options_.num_tables, options_.bits_per_table);
    books_->Reserve(layout.total, "image " + std::to_string(added.id));
    try {
      image.memory = std::make_shared<PooledDeviceBlock>(resources_, layout.total, "image features");
    } catch (...) {
      books_->Release(layout.total);  // the owner had no room: nothing was taken
      throw;
    }
    image.parts = layout.Parts(image.memory->as<void>(), image.num_features);
    // On the stream that hashes: the upload and the zeroed counts are
    // ordered before the hash launch (the streams do not sync with the
    // legacy default stream).
    uploads_.Upload(descriptors.data.data(), n * kDescriptorDim, image.parts.descriptors, stream_);
    CUDA_CHECK(cudaMemsetAsync(image.parts.offsets, 0, layout.offsets_bytes, stream_));
    pending_.push_back(added.id);
  }
  images_.emplace(added.id, std::move(image));
}

void GpuCascadeImageStore::Remove(image_t image_id) {
  const auto it = images_.find(image_id);
  if (it == images_.end()) return;
  // An image without features has no block. A held exact matcher may keep
  // the block a while longer; it is no longer this store's.
  if (it->second.memory) books_->Release(it->second.memory->bytes());
  images_.erase(it);
  pending_.erase(std::remove(pending_.begin(), pending_.end(), image_id), pending_.end());
}

const GpuCascadeImage& GpuCascadeImageStore::Find(image_t image_id) const {
  const auto it = images_.find(image_id);
  if (it == images_.end()) {
    throw std::invalid_argument("GPU matcher: image " + std::to_string(image_id) + " was not added");
  }
  return it->second;
}

void GpuCascadeImageStore::HashPending() {
  if (pending_.empty()) return;
  std::vector<HashJob> jobs;
  uint32_t blocks = 0;
  for (const image_t id : pending_) {
    const GpuCascadeImage& image = Find(id);
    HashJob job;
    job.parts = image.parts;
    job.block_begin = blocks;
    blocks += (image.num_features + kHashFeaturesPerBlock - 1) / kHashFeaturesPerBlock;
    jobs.push_back(job);
  }
  // Used on stream_ only, which is synchronised below: the block may go
  // back without waiting for the whole device.
  const PooledDeviceBlock device_jobs(resources_, jobs.size() * sizeof(HashJob), "hash jobs");
  CUDA_CHECK(cudaMemcpyAsync(device_jobs.as<HashJob>(), jobs.data(), jobs.size() * sizeof(HashJob),
                             cudaMemcpyHostToDevice, stream_));
  HashParams params;
  params.projections_t = projections_t_.as<float>();
  params.row_offsets = row_offsets_.as<float>();
  params.num_tables = options_.num_tables;
  params.bits_per_table = options_.bits_per_table;
  params.rows_padded = rows_padded_;
  LaunchHashAndBucket(device_jobs.as<HashJob>(), static_cast<int>(jobs.size()), blocks, params, stream_);
  CUDA_CHECK(cudaStreamSynchronize(stream_));
  pending_.clear();
}

void GpuCascadeImageStore::UploadProjections(const CascadeProjections& projections, const MeanDescriptor& mean) {
  const int rows = projections.num_rows();
  rows_padded_ = (rows + 31) / 32 * 32;
  std::vector<float> transposed(size_t(kDescriptorDim) * rows_padded_, 0.f);
  std::vector<float> offsets(rows_padded_, 0.f);
  int64_t rounded_mean[kDescriptorDim];
  for (int d = 0; d < kDescriptorDim; ++d) {
    rounded_mean[d] = static_cast<int64_t>(std::clamp(std::round(mean[d]), -32768.f, 32767.f));
  }
  for (int r = 0; r < rows; ++r) {
    int64_t offset = 0;
    for (int d = 0; d < kDescriptorDim; ++d) {
      const float v = projections.matrix[size_t(r) * kDescriptorDim + d];
      if (!(v >= -255.f && v <= 255.f) || v != std::round(v)) {
        throw std::runtime_error("GPU cascade matcher: projection entries must be integers in [-255, 255]");
      }
      transposed[size_t(d) * rows_padded_ + r] = v;
      offset += static_cast<int64_t>(v) * rounded_mean[d];
    }
    // |offset| <= 128 * 255 * 32767 could exceed 2^24 only for a mean out
    // of the descriptor range; then float rounding could flip a bit.
    offsets[r] = static_cast<float>(offset);
  }
  projections_t_.Allocate(resources_, transposed.size() * sizeof(float), "projections");
  row_offsets_.Allocate(resources_, offsets.size() * sizeof(float), "projection offsets");
  CUDA_CHECK(cudaMemcpy(projections_t_.as<float>(), transposed.data(), transposed.size() * sizeof(float),
                        cudaMemcpyHostToDevice));
  CUDA_CHECK(
      cudaMemcpy(row_offsets_.as<float>(), offsets.data(), offsets.size() * sizeof(float), cudaMemcpyHostToDevice));
  // Pageable copies may still be in flight on return; the hash kernels run
  // on non-blocking streams that do not wait for them.
  CUDA_CHECK(cudaDeviceSynchronize());
}

}  // namespace cuda
}  // namespace cashash
