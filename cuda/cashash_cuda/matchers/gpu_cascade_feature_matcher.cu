// The GPU Cascade Hashing FeatureMatcher.
//
// AddImage uploads descriptors into one allocation per image; the images
// added since the last MatchPairs are hashed and bucketed together in one
// launch sequence. MatchPairs cuts the pairs into batches, each matched by a
// few launches over all of its pairs; two batches alternate on two streams so
// that the host turns one batch's results into FeatureMatches while the next
// runs. Results are written by the device straight into mapped pinned memory.
#include "cashash_cuda/matchers/gpu_cascade_feature_matcher.h"

#include <cuda_runtime.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include "cashash/base/device_memory_error.h"
#include "cashash/base/object_pool.h"
#include "cashash/matching/cascade_hashing.h"
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#include "cashash_cuda/matching/brute_force_matcher.cuh"
#include "cashash_cuda/matching/cascade_hashing.cuh"
#include "cashash_cuda/matching/cascade_matcher.cuh"
#include "cashash_cuda/matching/cascade_matcher_tiles.cuh"
#include "cashash_cuda/matching/device_image.cuh"
#include "cashash_cuda/utils/device_memory.cuh"
#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/stream_priority.cuh"

namespace cashash {
namespace cuda {
namespace {

// A batch holds at most this many query features (forward direction) ...
constexpr size_t kMaxBatchQueries = size_t{1} << 22;
// ... and at most this many pairs ...
constexpr size_t kMaxBatchPairs = 8192;
// ... and candidate lists of at most this many bytes (tiled kernels): with
// 256 keys per list, 2 x 8192 features per pair take 17 MB, so ~60 such
// pairs per batch, ~1.2 ms of work at 50k pairs/s.
constexpr size_t kMaxBatchListBytes = size_t{1} << 30;

// Chunks of 32 A rows a tile warp takes before the rest of its bucket is
// shared out in a second pass (BigBucketQueue). 4: on one H100 it took the
// 300 x 16,384 street from 2.25-2.36 s to 2.08 s, where a few buckets of
// hundreds of features kept one warp busy past the rest of the launch, and
// left 8,192 features within the runs' spread; matches are identical. One
// warp per bucket split over 8 strips instead lost 0.4-0.6 s on every street.
constexpr uint32_t kBigBucketFirstChunks = 4;

// Queue entries per batch: far more than the buckets past a few chunks
// (about one per table and pair at 16,384 features), 512 KiB.
constexpr uint32_t kBigBucketCapacity = 65536;

// Under a budget each of the two batch slots grows within a sixteenth of it
// (a batch of a single pair that needs more may take up to half of what the
// images leave): the rest is for the exact rematch's kernels and the
// verifier, which take their memory from the same owner (GpuResources).
constexpr size_t kSlotShareOfBudget = 16;

std::string CheckGpuCascadeOptions(const CasHashOptions& options) {
  if (options.num_tables * options.bits_per_table > kMaxSignatureBits) {
    return "the GPU cascade matcher needs CasHash.num_tables * CasHash.bits_per_table <= " +
           std::to_string(kMaxSignatureBits) + ", got " +
           std::to_string(options.num_tables * options.bits_per_table);
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

// Scratch and result buffers of one in-flight batch.
struct BatchSlot {
  cudaStream_t stream = nullptr;
  cudaEvent_t done = nullptr;
  DeviceBuffer tasks;       // PairTask[]
  DeviceBuffer best;        // int32 per forward query
  DeviceBuffer cursor;      // one uint32
  DeviceBuffer list_keys;   // tiled kernels: kCandidateListCapacity uint32 per list row
  DeviceBuffer list_counts; // tiled kernels: uint32 per list row
  DeviceBuffer guides;      // guided matching: EpipolarGuideDevice per task
  DeviceBuffer big_buckets; // tiled kernels with a second pass: BigBucketQueue's entries and counters
  PinnedBuffer host_tasks;  // staging of PairTask[]
  PinnedBuffer host_guides; // staging of EpipolarGuideDevice[]
  size_t guide_capacity = 0;
  PinnedBuffer out;         // mapped: uint2 matches
  PinnedBuffer segments;    // mapped: MatchSegment per task
  size_t task_capacity = 0, query_capacity = 0, row_capacity = 0;
  // What is in flight: the pair index of each task.
  std::vector<size_t> pair_of_task;
  bool busy = false;
};

// Brute-force kernels for an exact-matching ticket run on another thread,
// on a stream of their own; a pool (ObjectPool) keeps one per thread that
// runs tickets at once.
class ExactKernels {
 public:
  ExactKernels(int device, std::shared_ptr<GpuResources> resources)
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
  // Also runs for kernels that failed half-way, which the ticket does not
  // give back: their stream may hold half a batch and goes with them.
  ~ExactKernels() {
    cudaSetDevice(device_);
    kernels_.reset();
    cudaStreamDestroy(stream_);
  }
  ExactKernels(const ExactKernels&) = delete;
  ExactKernels& operator=(const ExactKernels&) = delete;

  BruteForceKernels* kernels() { return kernels_.get(); }
  size_t scratch_bytes() const { return resources_->ScratchBytes(); }

 private:
  const int device_;
  std::shared_ptr<GpuResources> resources_;  // outlives kernels_
  cudaStream_t stream_ = nullptr;
  std::unique_ptr<BruteForceKernels> kernels_;
};
using ExactKernelsPool = ObjectPool<ExactKernels>;

// Exact matches of pairs from device descriptors the cascade matcher holds:
// the ticket keeps their blocks (and the owner they return to) until it goes.
class GpuExactMatchingTicket : public ExactMatchingTicket {
 public:
  GpuExactMatchingTicket(int device, std::shared_ptr<GpuResources> blocks, std::shared_ptr<ExactKernelsPool> kernels,
                         const MatchThresholds& thresholds)
      : device_(device), blocks_(std::move(blocks)), kernels_(std::move(kernels)), thresholds_(thresholds) {}
  ~GpuExactMatchingTicket() override {
    cudaSetDevice(device_);  // the blocks go back to a pool of this device
    held_.clear();
  }

  void Add(const std::shared_ptr<PooledDeviceBlock>& memory_a, DeviceDescriptors a,
           const std::shared_ptr<PooledDeviceBlock>& memory_b, DeviceDescriptors b) {
    if (memory_a) held_.push_back(memory_a);
    if (memory_b) held_.push_back(memory_b);
    pairs_.emplace_back(a, b);
  }

  std::vector<FeatureMatches> Run() override {
    CUDA_CHECK(cudaSetDevice(device_));
    std::unique_ptr<ExactKernels> lease = kernels_->Acquire();
    std::vector<FeatureMatches> matches =
        MatchPairsInBatches(lease->kernels(), pairs_, thresholds_, lease->scratch_bytes());
    kernels_->Release(std::move(lease));
    return matches;
  }

 private:
  const int device_;
  std::shared_ptr<GpuResources> blocks_;  // first in, last out: outlives held_
  std::shared_ptr<ExactKernelsPool> kernels_;
  const MatchThresholds thresholds_;
  std::vector<std::shared_ptr<PooledDeviceBlock>> held_;
  std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>> pairs_;
};

class GpuCascadeMatcher : public FeatureMatcher {
 public:
  GpuCascadeMatcher(const SiftMatchingOptions& sift_options, const CasHashOptions& options,
                    const MeanDescriptor& mean, const GpuMatcherConfig& config)
      : sift_options_(sift_options),
        options_(options),
        device_(config.gpu_index),
        tiled_(config.cascade_kernel == GpuCascadeKernel::kBucketTiles),
        list_capacity_(kCandidateListCapacity),
        resources_(config.resources ? config.resources
                                    : std::make_shared<GpuResources>(config.gpu_index, config.memory_budget_bytes)) {
    std::string error = sift_options.Check();
    if (error.empty()) error = options.Check();
    if (error.empty()) error = CheckGpuCascadeOptions(options);
    if (!error.empty()) throw std::invalid_argument(error);
    std::string reason;
    if (!CudaDeviceUsable(device_, &reason)) throw std::runtime_error(reason);
    CUDA_CHECK(cudaSetDevice(device_));
    if (resources_->device() != device_) throw std::invalid_argument("GPU cascade matcher: resources of another device");
    budget_ = MemoryBudget(resources_->budget_bytes());

    const CascadeProjections projections = GenerateCascadeProjections(options_);
    UploadProjections(projections, mean);
    for (BatchSlot& slot : slots_) {
      slot.stream = CreateStageStream(StreamRole::kMatching);
      CUDA_CHECK(cudaEventCreateWithFlags(&slot.done, cudaEventDisableTiming));
    }
    grid_size_ = CascadeMatchGridSize(device_);
    CUDA_CHECK(cudaDeviceGetAttribute(&sm_count_, cudaDevAttrMultiProcessorCount, device_));
  }

  ~GpuCascadeMatcher() override {
    cudaSetDevice(device_);
    exact_kernels_.reset();  // its scratch is used on slot 0's stream
    for (BatchSlot& slot : slots_) {
      if (slot.stream != nullptr) {
        cudaStreamSynchronize(slot.stream);
        cudaStreamDestroy(slot.stream);
      }
      if (slot.done != nullptr) cudaEventDestroy(slot.done);
    }
  }

  void AddImage(image_t image_id, const FeatureDescriptors& descriptors) override {
    CUDA_CHECK(cudaSetDevice(device_));
    RemoveImage(image_id);
    const size_t n = std::min(descriptors.rows(), static_cast<size_t>(sift_options_.max_num_matches));
    if (n >= kMaxGpuFeatures) {
      throw std::runtime_error("image " + std::to_string(image_id) + " has " + std::to_string(n) +
                               " features; the GPU matcher handles at most " +
                               std::to_string(kMaxGpuFeatures - 1) + " per image");
    }
    Image image;
    image.num_features = static_cast<uint32_t>(n);
    if (n > 0) {
      const DeviceImageLayout layout(n, options_.num_tables, options_.bits_per_table);
      Reserve(layout.total, "image " + std::to_string(image_id));
      try {
        image.memory = std::make_shared<PooledDeviceBlock>(resources_.get(), layout.total, "image features");
      } catch (...) {
        used_ -= layout.total;  // the owner had no room: nothing was taken
        throw;
      }
      image.parts = layout.Parts(image.memory->as<void>(), image.num_features);
      // On the stream that hashes: the upload and the zeroed counts are
      // ordered before the hash launch (the streams do not sync with the
      // legacy default stream).
      uploads_.Upload(descriptors.data.data(), n * kDescriptorDim, image.parts.descriptors, slots_[0].stream);
      CUDA_CHECK(cudaMemsetAsync(image.parts.offsets, 0, layout.offsets_bytes, slots_[0].stream));
      pending_.push_back(image_id);
    }
    images_.emplace(image_id, std::move(image));
  }

  void RemoveImage(image_t image_id) override {
    const auto it = images_.find(image_id);
    if (it == images_.end()) return;
    // An image without features has no block. A ticket may hold the block
    // a while longer (DeferExactMatching); it is no longer this matcher's.
    if (it->second.memory) used_ -= it->second.memory->bytes();
    images_.erase(it);
    pending_.erase(std::remove(pending_.begin(), pending_.end(), image_id), pending_.end());
  }

  std::vector<FeatureMatches> MatchPairs(const std::vector<ImagePair>& pairs) override {
    return MatchPairsImpl(pairs, nullptr, 0.0);
  }

  // Exact matches from the descriptors each image keeps on the device (the
  // rows AddImage uploaded, in the brute-force backend's layout): no second
  // upload, on the first batch slot's stream, which is idle between calls.
  bool SupportsExactMatching() const override { return true; }
  std::vector<FeatureMatches> MatchPairsExact(const std::vector<ImagePair>& pairs) override {
    CUDA_CHECK(cudaSetDevice(device_));
    if (!exact_kernels_) exact_kernels_ = std::make_unique<BruteForceKernels>(slots_[0].stream, resources_.get());
    std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>> device_pairs;
    device_pairs.reserve(pairs.size());
    for (const ImagePair& pair : pairs) {
      const Image& a = Find(pair.first);
      const Image& b = Find(pair.second);
      device_pairs.emplace_back(DeviceDescriptors{a.parts.descriptors, static_cast<int>(a.num_features)},
                                DeviceDescriptors{b.parts.descriptors, static_cast<int>(b.num_features)});
    }
    return MatchPairsInBatches(exact_kernels_.get(), device_pairs, ToMatchThresholds(sift_options_),
                               resources_->ScratchBytes());
  }

  // The pairs' device descriptors, lent to the ticket with their blocks:
  // the deferred rematch then reads what AddImage uploaded instead of
  // uploading it again (0.9 GB per 300-image street) beside the next
  // chunk's images.
  std::unique_ptr<ExactMatchingTicket> DeferExactMatching(const std::vector<ImagePair>& pairs) override {
    if (!ticket_kernels_) {
      ticket_kernels_ = std::make_shared<ExactKernelsPool>(
          [device = device_, resources = resources_] { return std::make_unique<ExactKernels>(device, resources); });
    }
    auto ticket = std::make_unique<GpuExactMatchingTicket>(device_, resources_, ticket_kernels_,
                                                           ToMatchThresholds(sift_options_));
    for (const ImagePair& pair : pairs) {
      const Image& a = Find(pair.first);
      const Image& b = Find(pair.second);
      ticket->Add(a.memory, DeviceDescriptors{a.parts.descriptors, static_cast<int>(a.num_features)}, b.memory,
                  DeviceDescriptors{b.parts.descriptors, static_cast<int>(b.num_features)});
    }
    return ticket;
  }

  bool SupportsEpipolarGuidance() const override { return true; }

  std::vector<FeatureMatches> MatchPairsGuided(const std::vector<GuidedPair>& guided, double max_distance) override {
    std::vector<ImagePair> pairs(guided.size());
    for (size_t i = 0; i < guided.size(); ++i) pairs[i] = guided[i].pair;
    return MatchPairsImpl(pairs, &guided, max_distance);
  }

  std::string Name() const override { return "gpu-cascade"; }

 private:
  // Matches `pairs`; with `guided` (same order), within the epipolar bands.
  std::vector<FeatureMatches> MatchPairsImpl(const std::vector<ImagePair>& pairs,
                                             const std::vector<GuidedPair>* guided, double max_distance) {
    CUDA_CHECK(cudaSetDevice(device_));
    HashPendingImages();
    std::vector<FeatureMatches> results(pairs.size());

    // Tasks in pair order, so that neighbouring warps share the target image.
    std::vector<PairTask> tasks;
    std::vector<size_t> pair_of_task;
    for (size_t i = 0; i < pairs.size(); ++i) {
      const Image& a = Find(pairs[i].first);
      const Image& b = Find(pairs[i].second);
      if (a.num_features == 0 || b.num_features == 0) continue;
      PairTask task;
      task.a = a.parts.View();
      task.b = b.parts.View();
      tasks.push_back(task);
      pair_of_task.push_back(i);
    }
    guides_.clear();
    guided_ = guided != nullptr;
    max_distance_ = max_distance;
    if (guided_) UploadGuidance(*guided, pair_of_task);

    int next_slot = 0;
    size_t start = 0;
    while (start < tasks.size()) {
      BatchSlot& slot = slots_[next_slot];
      next_slot ^= 1;
      if (slot.busy) Harvest(&slot, &results);
      const size_t end = BatchEnd(tasks, start);
      Launch(&slot, tasks, pair_of_task, start, end);
      start = end;
    }
    for (int k = 0; k < 2; ++k) {
      BatchSlot& slot = slots_[next_slot];
      next_slot ^= 1;
      if (slot.busy) Harvest(&slot, &results);
    }
    return results;
  }

  // Guided matching: every distinct keypoint array of the call in one device
  // buffer (float2 pixels), and guides_[task] with F and the offsets of the
  // task's two arrays in it.
  void UploadGuidance(const std::vector<GuidedPair>& guided, const std::vector<size_t>& pair_of_task) {
    // Each distinct array once: its offset and the rows the matcher holds.
    struct Placed {
      const std::vector<float>* xy;
      uint32_t offset;
      uint32_t rows;
    };
    std::unordered_map<const std::vector<float>*, size_t> index_of;
    std::vector<Placed> arrays;
    size_t total = 0;  // float2 entries
    auto place = [&](const std::vector<float>* xy, const Image& image, size_t pair) -> uint32_t {
      if (xy == nullptr || xy->size() < 2 * size_t(image.num_features)) {
        throw std::invalid_argument("GPU guided matching: pair " + std::to_string(pair) +
                                    " lacks keypoint positions for its features");
      }
      const auto it = index_of.find(xy);
      if (it != index_of.end()) {
        Placed& placed = arrays[it->second];
        if (placed.rows < image.num_features) {
          throw std::invalid_argument("GPU guided matching: one keypoint array given for images of different sizes");
        }
        return placed.offset;
      }
      if (total + image.num_features >= (size_t{1} << 32)) {
        throw std::runtime_error("GPU guided matching: too many keypoints in one call");
      }
      index_of.emplace(xy, arrays.size());
      arrays.push_back(Placed{xy, static_cast<uint32_t>(total), image.num_features});
      total += image.num_features;
      return arrays.back().offset;
    };
    guides_.resize(pair_of_task.size());
    for (size_t t = 0; t < pair_of_task.size(); ++t) {
      const GuidedPair& g = guided[pair_of_task[t]];
      std::copy(g.F.begin(), g.F.end(), guides_[t].F);
      guides_[t].points_a = place(g.points1, Find(g.pair.first), pair_of_task[t]);
      guides_[t].points_b = place(g.points2, Find(g.pair.second), pair_of_task[t]);
    }
    const size_t bytes = std::max<size_t>(total, 1) * sizeof(float2);
    if (points_.bytes() < bytes) {
      used_ -= points_.bytes();
      points_.Release();
      Reserve(bytes, "keypoint positions");
      points_.Allocate(resources_.get(), bytes, "keypoint positions");
    }
    std::vector<float2> staged(total);
    for (const Placed& placed : arrays) {
      const std::vector<float>& xy = *placed.xy;
      for (uint32_t i = 0; i < placed.rows; ++i) staged[placed.offset + i] = make_float2(xy[2 * i], xy[2 * i + 1]);
    }
    if (total > 0) {
      CUDA_CHECK(cudaMemcpyAsync(points_.as<float2>(), staged.data(), total * sizeof(float2),
                                 cudaMemcpyHostToDevice, slots_[0].stream));
      CUDA_CHECK(cudaStreamSynchronize(slots_[0].stream));
    }
  }
  struct Image {
    std::shared_ptr<PooledDeviceBlock> memory;  // shared with exact-matching tickets
    DeviceImageParts parts;
    uint32_t num_features = 0;
  };

  const Image& Find(image_t image_id) const {
    const auto it = images_.find(image_id);
    if (it == images_.end()) {
      throw std::invalid_argument("GPU matcher: image " + std::to_string(image_id) + " was not added");
    }
    return it->second;
  }

  // Accounts for `bytes` more device memory, or throws naming `what`.
  void Reserve(size_t bytes, const std::string& what) {
    if (bytes > budget_ || used_ > budget_ - bytes) {
      throw DeviceMemoryError("GPU memory budget exceeded by " + what + ": it needs " + MiB(bytes) + ", " +
                               MiB(used_) + " of " + MiB(budget_) +
                               " are in use; match fewer or smaller images per block");
    }
    used_ += bytes;
  }

  void UploadProjections(const CascadeProjections& projections, const MeanDescriptor& mean) {
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
    projections_t_.Allocate(resources_.get(), transposed.size() * sizeof(float), "projections");
    row_offsets_.Allocate(resources_.get(), offsets.size() * sizeof(float), "projection offsets");
    CUDA_CHECK(cudaMemcpy(projections_t_.as<float>(), transposed.data(), transposed.size() * sizeof(float),
                          cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(row_offsets_.as<float>(), offsets.data(), offsets.size() * sizeof(float),
                          cudaMemcpyHostToDevice));
    // Pageable copies may still be in flight on return; the hash kernels run
    // on non-blocking streams that do not wait for them.
    CUDA_CHECK(cudaDeviceSynchronize());
  }

  // Hashes and buckets every image added since the last call, in one launch.
  void HashPendingImages() {
    if (pending_.empty()) return;
    std::vector<HashJob> jobs;
    uint32_t blocks = 0;
    for (const image_t id : pending_) {
      const Image& image = Find(id);
      HashJob job;
      job.parts = image.parts;
      job.block_begin = blocks;
      blocks += (image.num_features + kHashFeaturesPerBlock - 1) / kHashFeaturesPerBlock;
      jobs.push_back(job);
    }
    // Used on slots_[0]'s stream only, which is synchronised below: the
    // block may go back without waiting for the whole device.
    const PooledDeviceBlock device_jobs(resources_.get(), jobs.size() * sizeof(HashJob), "hash jobs");
    CUDA_CHECK(cudaMemcpyAsync(device_jobs.as<HashJob>(), jobs.data(), jobs.size() * sizeof(HashJob),
                               cudaMemcpyHostToDevice, slots_[0].stream));
    HashParams params;
    params.projections_t = projections_t_.as<float>();
    params.row_offsets = row_offsets_.as<float>();
    params.num_tables = options_.num_tables;
    params.bits_per_table = options_.bits_per_table;
    params.rows_padded = rows_padded_;
    LaunchHashAndBucket(device_jobs.as<HashJob>(), static_cast<int>(jobs.size()), blocks, params,
                        slots_[0].stream);
    CUDA_CHECK(cudaStreamSynchronize(slots_[0].stream));
    pending_.clear();
  }

  // Bytes of the candidate lists of `rows` features (tiled kernels).
  size_t ListBytes(size_t rows) const {
    return tiled_ ? rows * (list_capacity_ + 1) * sizeof(uint32_t) : 0;
  }

  // Device bytes of a batch slot sized for `tasks` pairs, `queries` forward
  // queries and `rows` list rows (features of both sides).
  size_t SlotBytes(size_t tasks, size_t queries, size_t rows) const {
    return tasks * sizeof(PairTask) + queries * sizeof(int32_t) + ListBytes(rows) + 512;
  }

  // End of the batch starting at `start`: bounded by kMaxBatch* and by the
  // memory budget left for the two slots: a batch grows within its share
  // (kSlotShareOfBudget) and takes at least one pair where that pair fits
  // half of what the images leave.
  size_t BatchEnd(const std::vector<PairTask>& tasks, size_t start) const {
    size_t free_for_slots = std::numeric_limits<size_t>::max();
    size_t most_for_one_pair = std::numeric_limits<size_t>::max();
    if (budget_ != std::numeric_limits<size_t>::max()) {
      size_t slots_now = 0;
      for (const BatchSlot& s : slots_) slots_now += SlotBytes(s.task_capacity, s.query_capacity, s.row_capacity);
      const size_t images = used_ - slots_now;
      free_for_slots = budget_ / kSlotShareOfBudget;
      most_for_one_pair = budget_ > images ? (budget_ - images) / 2 : 0;
    }
    size_t end = start, queries = 0, rows = 0;
    while (end < tasks.size() && end - start < kMaxBatchPairs) {
      const size_t q = tasks[end].a.num_features;
      const size_t r = q + tasks[end].b.num_features;
      if (end > start && (queries + q > kMaxBatchQueries || ListBytes(rows + r) > kMaxBatchListBytes ||
                          SlotBytes(end + 1 - start, queries + q, rows + r) > free_for_slots)) {
        break;
      }
      if (end == start && SlotBytes(1, q, r) > most_for_one_pair) {
        throw DeviceMemoryError("GPU memory budget too small to match a pair of " + std::to_string(q) + " and " +
                                 std::to_string(r - q) + " features: " + MiB(SlotBytes(1, q, r)) +
                                 " of scratch needed, " + MiB(most_for_one_pair) + " left");
      }
      queries += q;
      rows += r;
      ++end;
    }
    return end;
  }

  // Grows the slot's buffers to hold `num_tasks` pairs, `queries` queries
  // and `rows` list rows.
  void EnsureCapacity(BatchSlot* slot, size_t num_tasks, size_t queries, size_t rows) {
    if (num_tasks <= slot->task_capacity && queries <= slot->query_capacity && rows <= slot->row_capacity) return;
    const size_t new_tasks = std::max(num_tasks, slot->task_capacity);
    const size_t new_queries = std::max(queries, slot->query_capacity);
    const size_t new_rows = std::max(rows, slot->row_capacity);
    used_ -= SlotBytes(slot->task_capacity, slot->query_capacity, slot->row_capacity);
    slot->tasks.Release();
    slot->best.Release();
    slot->list_keys.Release();
    slot->list_counts.Release();
    slot->task_capacity = slot->query_capacity = slot->row_capacity = 0;
    Reserve(SlotBytes(new_tasks, new_queries, new_rows), "matching scratch");
    GpuResources* owner = resources_.get();
    slot->tasks.Allocate(owner, new_tasks * sizeof(PairTask), "pair tasks");
    slot->best.Allocate(owner, new_queries * sizeof(int32_t), "match results");
    if (tiled_ && new_rows > 0) {
      slot->list_keys.Allocate(owner, new_rows * list_capacity_ * sizeof(uint32_t), "candidate lists");
      slot->list_counts.Allocate(owner, new_rows * sizeof(uint32_t), "candidate list counts");
    }
    if (slot->cursor.bytes() == 0) slot->cursor.Allocate(owner, 256, "match cursor");
    slot->host_tasks.Allocate(owner, new_tasks * sizeof(PairTask), "pair tasks");
    slot->segments.Allocate(owner, new_tasks * sizeof(MatchSegment), "match segments");
    slot->out.Allocate(owner, new_queries * sizeof(uint2), "matches");
    slot->task_capacity = new_tasks;
    slot->query_capacity = new_queries;
    slot->row_capacity = new_rows;
  }

  // One function because a batch's staging (task offsets, items, rows), uploads,
  // memsets and kernels are enqueued in this order on slot->stream, the later
  // launches reading the sizes summed first.
  void Launch(BatchSlot* slot, const std::vector<PairTask>& all_tasks, const std::vector<size_t>& pair_of_task,
              size_t start, size_t end) {
    const size_t num_tasks = end - start;
    size_t queries = 0, rows = 0;
    uint32_t items = 0;
    for (size_t k = start; k < end; ++k) {
      queries += all_tasks[k].a.num_features;
      rows += all_tasks[k].a.num_features + all_tasks[k].b.num_features;
    }
    EnsureCapacity(slot, num_tasks, queries, rows);
    PairTask* staged = slot->host_tasks.host<PairTask>();
    uint32_t offset = 0, row = 0;
    for (size_t k = 0; k < num_tasks; ++k) {
      staged[k] = all_tasks[start + k];
      staged[k].best_offset = offset;
      staged[k].item_begin = items;
      staged[k].list_offset = row;
      offset += staged[k].a.num_features;
      row += staged[k].a.num_features + staged[k].b.num_features;
      items += (staged[k].a.num_features + kQueriesPerItem - 1) / kQueriesPerItem;
    }
    slot->pair_of_task.assign(pair_of_task.begin() + start, pair_of_task.begin() + end);
    CUDA_CHECK(cudaMemcpyAsync(slot->tasks.as<PairTask>(), staged, num_tasks * sizeof(PairTask),
                               cudaMemcpyHostToDevice, slot->stream));
    if (guided_) {
      if (slot->guide_capacity < num_tasks) {
        used_ -= slot->guides.bytes();
        slot->guides.Release();
        slot->guide_capacity = 0;
        Reserve(num_tasks * sizeof(EpipolarGuideDevice), "epipolar guides");
        slot->guides.Allocate(resources_.get(), num_tasks * sizeof(EpipolarGuideDevice), "epipolar guides");
        slot->host_guides.Allocate(resources_.get(), num_tasks * sizeof(EpipolarGuideDevice), "epipolar guides");
        slot->guide_capacity = num_tasks;
      }
      EpipolarGuideDevice* staged_guides = slot->host_guides.host<EpipolarGuideDevice>();
      std::copy(guides_.begin() + start, guides_.begin() + end, staged_guides);
      CUDA_CHECK(cudaMemcpyAsync(slot->guides.as<EpipolarGuideDevice>(), staged_guides,
                                 num_tasks * sizeof(EpipolarGuideDevice), cudaMemcpyHostToDevice, slot->stream));
    }
    CUDA_CHECK(cudaMemsetAsync(slot->cursor.as<uint32_t>(), 0, sizeof(uint32_t), slot->stream));
    MatchParams params;
    params.num_tables = options_.num_tables;
    params.bits_per_table = options_.bits_per_table;
    params.tau = options_.tau;
    params.top_k = options_.top_k;
    params.max_ratio = static_cast<float>(sift_options_.max_ratio);
    params.max_distance = static_cast<float>(sift_options_.max_distance);
    for (int field = 0; field * options_.bits_per_table < 64; ++field) {
      const int low = field * options_.bits_per_table;
      const int high = std::min(low + options_.bits_per_table, 64) - 1;
      params.field_low_bits |= uint64_t{1} << low;
      params.field_high_bits |= uint64_t{1} << high;
    }
    if (tiled_) {
      CandidateLists lists;
      lists.keys = slot->list_keys.as<uint32_t>();
      lists.counts = slot->list_counts.as<uint32_t>();
      lists.capacity = list_capacity_;
      CUDA_CHECK(cudaMemsetAsync(lists.counts, 0, rows * sizeof(uint32_t), slot->stream));
      BigBucketQueue big;
      {
        const size_t entry_bytes = size_t{kBigBucketCapacity} * sizeof(uint2);
        if (slot->big_buckets.bytes() == 0) {
          slot->big_buckets.Allocate(resources_.get(), entry_bytes + 64, "big-bucket queue");
        }
        char* base = slot->big_buckets.as<char>();
        big.entries = reinterpret_cast<uint2*>(base);
        big.capacity = kBigBucketCapacity;
        big.header = reinterpret_cast<unsigned long long*>(base + entry_bytes);
        big.cursor = reinterpret_cast<uint32_t*>(base + entry_bytes + 8);
        big.overflow_base = reinterpret_cast<uint32_t*>(base + entry_bytes + 12);
        big.first_chunks = kBigBucketFirstChunks;
        big.warps = static_cast<unsigned>(sm_count_) * 32u;
      }
      LaunchCascadeTiles(slot->tasks.as<PairTask>(), static_cast<int>(num_tasks), params, lists, slot->stream, big);
      if (guided_) {
        LaunchCascadeSelectGuided(slot->tasks.as<PairTask>(), static_cast<int>(num_tasks), items, params, lists,
                                  slot->guides.as<EpipolarGuideDevice>(), points_.as<float2>(), max_distance_,
                                  sift_options_.cross_check, grid_size_, slot->best.as<int32_t>(), slot->stream);
      } else {
        LaunchCascadeSelect(slot->tasks.as<PairTask>(), static_cast<int>(num_tasks), items, params, lists,
                            sift_options_.cross_check, grid_size_, slot->best.as<int32_t>(), slot->stream);
      }
    } else if (guided_) {
      LaunchCascadeMatchGuided(slot->tasks.as<PairTask>(), static_cast<int>(num_tasks), items, params,
                               slot->guides.as<EpipolarGuideDevice>(), points_.as<float2>(), max_distance_,
                               sift_options_.cross_check, grid_size_, slot->best.as<int32_t>(), slot->stream);
    } else {
      LaunchCascadeMatch(slot->tasks.as<PairTask>(), static_cast<int>(num_tasks), items, params,
                         sift_options_.cross_check, grid_size_, slot->best.as<int32_t>(), slot->stream);
    }
    LaunchCompactMatches(slot->tasks.as<PairTask>(), static_cast<int>(num_tasks), slot->best.as<int32_t>(),
                         slot->out.device<uint2>(), slot->segments.device<MatchSegment>(),
                         slot->cursor.as<uint32_t>(), slot->stream);
    CUDA_CHECK(cudaEventRecord(slot->done, slot->stream));
    slot->busy = true;
  }

  void Harvest(BatchSlot* slot, std::vector<FeatureMatches>* results) {
    CUDA_CHECK(cudaEventSynchronize(slot->done));
    const MatchSegment* segments = slot->segments.host<MatchSegment>();
    const uint2* out = slot->out.host<uint2>();
    for (size_t k = 0; k < slot->pair_of_task.size(); ++k) {
      FeatureMatches& matches = (*results)[slot->pair_of_task[k]];
      const uint2* first = out + segments[k].begin;
      matches.resize(segments[k].count);
      for (uint32_t m = 0; m < segments[k].count; ++m) matches[m] = FeatureMatch{first[m].x, first[m].y};
    }
    slot->busy = false;
  }

  const SiftMatchingOptions sift_options_;
  const CasHashOptions options_;
  const int device_;
  const bool tiled_;
  int sm_count_ = 1;
  const int list_capacity_;
  // First in, last out: every buffer, block and ticket below returns to it.
  std::shared_ptr<GpuResources> resources_;
  size_t budget_ = 0;
  size_t used_ = 0;
  int rows_padded_ = 0;
  int grid_size_ = 1;
  DeviceBuffer projections_t_;
  DeviceBuffer row_offsets_;
  std::unordered_map<image_t, Image> images_;
  std::vector<image_t> pending_;
  PinnedUploadRing uploads_{resources_.get()};  // descriptors to the device, on slots_[0]'s stream
  BatchSlot slots_[2];
  // MatchPairsExact's kernels and scratch, made on first use.
  std::unique_ptr<BruteForceKernels> exact_kernels_;
  // The tickets' kernels, each with a stream of its own.
  std::shared_ptr<ExactKernelsPool> ticket_kernels_;
  // Guided matching (MatchPairsGuided): guides of the current call's tasks,
  // the keypoint pixels they point into, the band half-width.
  std::vector<EpipolarGuideDevice> guides_;
  DeviceBuffer points_;
  bool guided_ = false;
  double max_distance_ = 0;
};

}  // namespace

std::unique_ptr<FeatureMatcher> CreateGpuCascadeMatcher(const SiftMatchingOptions& sift_options,
                                                        const CasHashOptions& cashash_options,
                                                        const MeanDescriptor& mean, const GpuMatcherConfig& config) {
  return std::make_unique<GpuCascadeMatcher>(sift_options, cashash_options, mean, config);
}

}  // namespace cuda
}  // namespace cashash
