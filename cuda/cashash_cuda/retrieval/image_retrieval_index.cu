#include "cashash_cuda/retrieval/image_retrieval_index.h"

#include <cuda_runtime.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

#include "cashash/base/device_memory_error.h"
#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/device_memory.cuh"
#include "cashash_cuda/utils/warp_primitives.cuh"

namespace cashash {
namespace cuda {
namespace {

static_assert(sizeof(size_t) == sizeof(uint64_t), "the index's offsets go to the device as 64-bit words");
static_assert(sizeof(RetrievalQueryWord) == 8 && sizeof(RetrievalPosting) == 8, "8-byte records on both sides");

constexpr int kThreads = 512;
constexpr int kWarps = kThreads / 32;
// 2^31 as a float: a product times it is exact (a power of two).
constexpr float kScoreScale = 2147483648.f;
// What one batch of queries may take on the device: their words and
// their results.
constexpr size_t kBatchBytes = size_t{256} << 20;

// Block q of the grid's x is query q of the batch, the grid's y is its tile
// of images [tile * tile_size, min(num_images, tile * tile_size +
// tile_size)). Writes the tile's best min(k, candidates) (score in units
// of kGpuRetrievalScoreStep, image position) to slot (q, tile), in no
// particular order (the host sorts them), and their number to
// out_counts[slot]. Dynamic shared memory: tile_size 32-bit scores.
__global__ void __launch_bounds__(kThreads)
    RetrievalTopKKernel(const uint64_t* __restrict__ posting_offsets, const RetrievalPosting* __restrict__ postings,
                        const uint64_t* __restrict__ query_offsets, const RetrievalQueryWord* __restrict__ query_words,
                        const uint32_t* __restrict__ query_images, uint32_t num_images, uint32_t tile_size,
                        uint32_t k, uint32_t* __restrict__ out_scores, uint32_t* __restrict__ out_images,
                        uint32_t* __restrict__ out_counts) {
  extern __shared__ uint32_t scores[];
  __shared__ uint32_t histogram[256];
  __shared__ uint32_t warp_counts[kWarps];
  __shared__ uint32_t threshold_prefix, threshold_remaining, take_all_flag, written;

  const uint32_t tid = threadIdx.x;
  const uint32_t lane = tid & 31u;
  const uint32_t warp = tid >> 5;
  const uint32_t tile_begin = blockIdx.y * tile_size;
  const uint32_t size = min(num_images, tile_begin + tile_size) - tile_begin;
  const uint64_t slot = static_cast<uint64_t>(blockIdx.x) * gridDim.y + blockIdx.y;

  for (uint32_t i = tid; i < size; i += kThreads) scores[i] = 0;
  __syncthreads();

  // Scores: each warp takes 32 query words at a time (one coalesced load),
  // then their posting lists one after the other, a lane per posting. A
  // word's postings name distinct images, so the lanes of one atomicAdd
  // never wait on each other's address.
  const uint64_t words_begin = query_offsets[blockIdx.x];
  const uint64_t words_end = query_offsets[blockIdx.x + 1];
  for (uint64_t base = words_begin + warp * 32u; base < words_end; base += kThreads) {
    uint64_t begin = 0, end = 0;
    float weight = 0.f;
    if (base + lane < words_end) {
      const RetrievalQueryWord word = query_words[base + lane];
      weight = word.weight;
      begin = posting_offsets[word.word];
      end = posting_offsets[word.word + 1];
    }
    const int words = words_end - base < 32 ? static_cast<int>(words_end - base) : 32;
    for (int j = 0; j < words; ++j) {
      const uint64_t p_begin = __shfl_sync(kFullWarpMask, begin, j);
      const uint64_t p_end = __shfl_sync(kFullWarpMask, end, j);
      const float w = __shfl_sync(kFullWarpMask, weight, j);
      for (uint64_t p = p_begin + lane; p < p_end; p += 32) {
        const RetrievalPosting posting = postings[p];
        const uint32_t local = posting.image - tile_begin;  // wraps below the tile
        if (local < size) {
          // One rounding per term, at least one unit: integer sums do not
          // depend on the order of the additions, and a shared word always
          // counts. A cosine is at most 1 = 2^31 units, so the sum fits.
          const uint32_t units = max(1u, __float2uint_rn(__fmul_rn(w, posting.weight) * kScoreScale));
          atomicAdd(&scores[local], units);
        }
      }
    }
  }
  __syncthreads();
  const uint32_t self = query_images[blockIdx.x] - tile_begin;
  if (tid == 0) {
    if (self < size) scores[self] = 0;  // never its own neighbour
    threshold_prefix = 0;
    threshold_remaining = k;
    take_all_flag = 0;
    written = 0;
  }
  __syncthreads();

  // The k-th largest nonzero score, a byte at a time from the top (radix
  // select): after the four passes `threshold_prefix` is that score and
  // `threshold_remaining` how many of the images holding it are kept. With
  // k or fewer nonzero scores, every one is kept.
  uint32_t mask = 0;
  for (int shift = 24; shift >= 0; shift -= 8) {
    for (uint32_t b = tid; b < 256; b += kThreads) histogram[b] = 0;
    __syncthreads();
    const uint32_t prefix = threshold_prefix;
    for (uint32_t i = tid; i < size; i += kThreads) {
      const uint32_t s = scores[i];
      if (s != 0 && (s & mask) == prefix) atomicAdd(&histogram[(s >> shift) & 255u], 1u);
    }
    __syncthreads();
    if (tid == 0) {
      const uint32_t remaining = threshold_remaining;
      uint32_t above = 0;
      int bin = 255;
      for (; bin >= 0; --bin) {
        if (above + histogram[bin] >= remaining) break;
        above += histogram[bin];
      }
      if (bin < 0) {
        take_all_flag = 1;  // only in the first pass: fewer than k nonzero scores
      } else {
        threshold_prefix = prefix | (static_cast<uint32_t>(bin) << shift);
        threshold_remaining = remaining - above;
      }
    }
    __syncthreads();
    if (take_all_flag) break;
    mask |= 255u << shift;
  }
  const bool take_all = take_all_flag != 0;
  const uint32_t threshold = threshold_prefix;
  const uint32_t ties = take_all ? 0 : threshold_remaining;

  uint32_t* slot_scores = out_scores + slot * k;
  uint32_t* slot_images = out_images + slot * k;
  // Above the threshold (or every nonzero score): fewer than k, any order.
  for (uint32_t i = tid; i < size; i += kThreads) {
    const uint32_t s = scores[i];
    if (s != 0 && (take_all || s > threshold)) {
      const uint32_t at = atomicAdd(&written, 1u);
      slot_scores[at] = s;
      slot_images[at] = tile_begin + i;
    }
  }
  __syncthreads();
  const uint32_t above_count = written;
  // At the threshold: the `ties` lowest positions, found in position order
  // (a block-wide count of the earlier ones), so the choice is the CPU's.
  uint32_t taken = 0;
  for (uint32_t base = 0; base < size && taken < ties; base += kThreads) {
    const uint32_t i = base + tid;
    const bool tie = i < size && scores[i] == threshold;
    const unsigned ballot = __ballot_sync(kFullWarpMask, tie);
    if (lane == 0) warp_counts[warp] = __popc(ballot);
    __syncthreads();
    uint32_t before = 0, total = 0;
    for (int w = 0; w < kWarps; ++w) {
      before += static_cast<uint32_t>(w) < warp ? warp_counts[w] : 0u;
      total += warp_counts[w];
    }
    const uint32_t rank = taken + before + __popc(ballot & ((1u << lane) - 1u));
    if (tie && rank < ties) {
      slot_scores[above_count + rank] = threshold;
      slot_images[above_count + rank] = tile_begin + i;
    }
    taken += total;
    __syncthreads();  // warp_counts is rewritten next round
  }
  if (tid == 0) out_counts[slot] = above_count + ties;
}

// Makes the resources' device current for the scope.
class DeviceScope {
 public:
  explicit DeviceScope(int device) {
    CUDA_CHECK(cudaGetDevice(&previous_));
    if (previous_ != device) CUDA_CHECK(cudaSetDevice(device));
  }
  ~DeviceScope() { cudaSetDevice(previous_); }
  DeviceScope(const DeviceScope&) = delete;
  DeviceScope& operator=(const DeviceScope&) = delete;

 private:
  int previous_ = 0;
};

class Stream {
 public:
  Stream() { CUDA_CHECK(cudaStreamCreateWithFlags(&stream_, cudaStreamNonBlocking)); }
  ~Stream() {
    cudaStreamSynchronize(stream_);
    cudaStreamDestroy(stream_);
  }
  Stream(const Stream&) = delete;
  Stream& operator=(const Stream&) = delete;
  cudaStream_t get() const { return stream_; }

 private:
  cudaStream_t stream_ = nullptr;
};

// Images per tile: `wanted` (0: no wish) within what one block's shared
// memory holds on the current device; sets the kernel's dynamic shared
// memory to the tile's size.
uint32_t ImagesPerTile(size_t num_images, size_t wanted, uint32_t* num_tiles) {
  int device = 0;
  CUDA_CHECK(cudaGetDevice(&device));
  int opt_in_bytes = 0;
  CUDA_CHECK(cudaDeviceGetAttribute(&opt_in_bytes, cudaDevAttrMaxSharedMemoryPerBlockOptin, device));
  cudaFuncAttributes attributes{};
  CUDA_CHECK(cudaFuncGetAttributes(&attributes, RetrievalTopKKernel));
  const size_t free_bytes = static_cast<size_t>(std::max(0, opt_in_bytes - static_cast<int>(attributes.sharedSizeBytes)));
  size_t most = free_bytes / sizeof(uint32_t);
  if (wanted > 0) most = std::min(most, wanted);
  if (most == 0) throw std::runtime_error("GPU retrieval: no shared memory for the scores");
  const size_t tiles = (num_images + most - 1) / most;
  const size_t per_tile = (num_images + tiles - 1) / tiles;  // even tiles
  *num_tiles = static_cast<uint32_t>(tiles);
  CUDA_CHECK(cudaFuncSetAttribute(RetrievalTopKKernel, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                  static_cast<int>(per_tile * sizeof(uint32_t))));
  return static_cast<uint32_t>(per_tile);
}

// Consecutive runs of `query_images` whose words and results fit
// `batch_bytes`: [starts[b], starts[b + 1]).
std::vector<size_t> BatchStarts(const RetrievalIndexView& index, const std::vector<uint32_t>& query_images,
                                size_t result_bytes_per_query, size_t batch_bytes) {
  std::vector<size_t> starts = {0};
  size_t bytes = 0;
  for (size_t q = 0; q < query_images.size(); ++q) {
    const uint32_t image = query_images[q];
    const size_t query_bytes = (index.query_offsets[image + 1] - index.query_offsets[image]) *
                                   sizeof(RetrievalQueryWord) +
                               result_bytes_per_query + sizeof(uint64_t) + sizeof(uint32_t);
    if (bytes > 0 && bytes + query_bytes > batch_bytes) {
      starts.push_back(q);
      bytes = 0;
    }
    bytes += query_bytes;
  }
  starts.push_back(query_images.size());
  return starts;
}

}  // namespace

size_t GpuRetrievalResidentBytes(const RetrievalIndexView& index) {
  return (static_cast<size_t>(index.vocabulary_size) + 1) * sizeof(uint64_t) +
         index.num_postings() * sizeof(RetrievalPosting);
}

std::vector<std::vector<RetrievalNeighbor>> GpuTopK(const RetrievalIndexView& index,
                                                    const std::vector<uint32_t>& query_images, size_t k,
                                                    const GpuRetrievalConfig& config, GpuRetrievalStats* stats) {
  const size_t n = index.num_images;
  for (uint32_t image : query_images) {
    if (image >= n) {
      throw std::out_of_range("GpuTopK: image " + std::to_string(image) + " of " + std::to_string(n));
    }
  }
  if (config.resources == nullptr) throw std::invalid_argument("GpuTopK: no GpuResources");
  if (n > UINT32_MAX) throw std::invalid_argument("GpuTopK: more images than 32-bit positions");
  std::vector<std::vector<RetrievalNeighbor>> result(query_images.size());
  if (query_images.empty() || k == 0 || n < 2) return result;
  GpuResources* resources = config.resources;
  DeviceScope scope(resources->device());
  Stream stream;

  uint32_t num_tiles = 1;
  const uint32_t tile_size = ImagesPerTile(n, config.max_images_per_tile, &num_tiles);
  // A tile keeps at most k, and never more than its images.
  const uint32_t kept = static_cast<uint32_t>(std::min<size_t>(k, tile_size));

  // The postings and word offsets, for the whole call.
  DeviceBuffer posting_offsets(resources, (static_cast<size_t>(index.vocabulary_size) + 1) * sizeof(uint64_t),
                               "retrieval word offsets");
  DeviceBuffer postings(resources, index.num_postings() * sizeof(RetrievalPosting), "retrieval postings");
  CUDA_CHECK(cudaMemcpyAsync(posting_offsets.as<void>(), index.posting_offsets, posting_offsets.bytes(),
                             cudaMemcpyHostToDevice, stream.get()));
  if (postings.bytes() > 0) {
    CUDA_CHECK(cudaMemcpyAsync(postings.as<void>(), index.postings, postings.bytes(), cudaMemcpyHostToDevice,
                               stream.get()));
  }

  // The batches' buffers, sized for the largest batch; halved while the
  // budget has no room for them.
  const size_t result_bytes_per_query = static_cast<size_t>(num_tiles) * (kept * 2 * sizeof(uint32_t) + sizeof(uint32_t));
  size_t batch_bytes = kBatchBytes;
  std::vector<size_t> starts;
  DeviceBuffer words_buffer, offsets_buffer, images_buffer, scores_buffer, positions_buffer, counts_buffer;
  for (;;) {
    starts = BatchStarts(index, query_images, result_bytes_per_query, batch_bytes);
    size_t most_words = 0, most_queries = 0;
    for (size_t b = 0; b + 1 < starts.size(); ++b) {
      size_t words = 0;
      for (size_t q = starts[b]; q < starts[b + 1]; ++q) {
        words += index.query_offsets[query_images[q] + 1] - index.query_offsets[query_images[q]];
      }
      most_words = std::max(most_words, words);
      most_queries = std::max(most_queries, starts[b + 1] - starts[b]);
    }
    try {
      words_buffer.Allocate(resources, most_words * sizeof(RetrievalQueryWord), "retrieval query words");
      offsets_buffer.Allocate(resources, (most_queries + 1) * sizeof(uint64_t), "retrieval query offsets");
      images_buffer.Allocate(resources, most_queries * sizeof(uint32_t), "retrieval query images");
      const size_t slots = most_queries * num_tiles;
      scores_buffer.Allocate(resources, slots * kept * sizeof(uint32_t), "retrieval result scores");
      positions_buffer.Allocate(resources, slots * kept * sizeof(uint32_t), "retrieval result images");
      counts_buffer.Allocate(resources, slots * sizeof(uint32_t), "retrieval result counts");
      break;
    } catch (const DeviceMemoryError&) {
      // One query per batch is the least there is.
      if (most_queries <= 1) throw;
      batch_bytes /= 2;
    }
  }

  std::vector<uint64_t> batch_offsets;
  std::vector<RetrievalQueryWord> batch_words;
  std::vector<uint32_t> batch_images;
  std::vector<uint32_t> out_scores, out_images, out_counts;
  std::vector<std::pair<uint32_t, uint32_t>> candidates;  // (units, image)
  for (size_t b = 0; b + 1 < starts.size(); ++b) {
    const size_t first = starts[b], count = starts[b + 1] - starts[b];
    batch_offsets.assign(1, 0);
    batch_words.clear();
    batch_images.assign(query_images.begin() + static_cast<std::ptrdiff_t>(first),
                        query_images.begin() + static_cast<std::ptrdiff_t>(first + count));
    // Consecutive images (every image's search) have their words in one
    // piece of the index: sent from there, without a copy on the host.
    bool consecutive = true;
    for (size_t q = 1; q < count && consecutive; ++q) consecutive = batch_images[q] == batch_images[0] + q;
    const RetrievalQueryWord* words = index.queries + index.query_offsets[batch_images.front()];
    for (uint32_t image : batch_images) {
      const size_t size = index.query_offsets[image + 1] - index.query_offsets[image];
      if (!consecutive) {
        batch_words.insert(batch_words.end(), index.queries + index.query_offsets[image],
                           index.queries + index.query_offsets[image + 1]);
      }
      batch_offsets.push_back(batch_offsets.back() + size);
    }
    if (!consecutive) words = batch_words.data();
    if (batch_offsets.back() > 0) {
      CUDA_CHECK(cudaMemcpyAsync(words_buffer.as<void>(), words, batch_offsets.back() * sizeof(RetrievalQueryWord),
                                 cudaMemcpyHostToDevice, stream.get()));
    }
    CUDA_CHECK(cudaMemcpyAsync(offsets_buffer.as<void>(), batch_offsets.data(),
                               batch_offsets.size() * sizeof(uint64_t), cudaMemcpyHostToDevice, stream.get()));
    CUDA_CHECK(cudaMemcpyAsync(images_buffer.as<void>(), batch_images.data(), count * sizeof(uint32_t),
                               cudaMemcpyHostToDevice, stream.get()));
    const dim3 grid(static_cast<unsigned>(count), num_tiles);
    RetrievalTopKKernel<<<grid, kThreads, tile_size * sizeof(uint32_t), stream.get()>>>(
        posting_offsets.as<uint64_t>(), postings.as<RetrievalPosting>(), offsets_buffer.as<uint64_t>(),
        words_buffer.as<RetrievalQueryWord>(), images_buffer.as<uint32_t>(), static_cast<uint32_t>(n), tile_size,
        kept, scores_buffer.as<uint32_t>(), positions_buffer.as<uint32_t>(), counts_buffer.as<uint32_t>());
    CUDA_CHECK_LAUNCH();
    const size_t slots = count * num_tiles;
    out_scores.resize(slots * kept);
    out_images.resize(slots * kept);
    out_counts.resize(slots);
    CUDA_CHECK(cudaMemcpyAsync(out_counts.data(), counts_buffer.as<void>(), slots * sizeof(uint32_t),
                               cudaMemcpyDeviceToHost, stream.get()));
    CUDA_CHECK(cudaMemcpyAsync(out_scores.data(), scores_buffer.as<void>(), slots * kept * sizeof(uint32_t),
                               cudaMemcpyDeviceToHost, stream.get()));
    CUDA_CHECK(cudaMemcpyAsync(out_images.data(), positions_buffer.as<void>(), slots * kept * sizeof(uint32_t),
                               cudaMemcpyDeviceToHost, stream.get()));
    CUDA_CHECK(cudaStreamSynchronize(stream.get()));

    // The tiles' lists merged by the CPU's rule, on the integer scores (two
    // scores a unit apart may round to the same float).
    for (size_t q = 0; q < count; ++q) {
      candidates.clear();
      for (uint32_t tile = 0; tile < num_tiles; ++tile) {
        const size_t slot = q * num_tiles + tile;
        for (uint32_t c = 0; c < out_counts[slot]; ++c) {
          candidates.emplace_back(out_scores[slot * kept + c], out_images[slot * kept + c]);
        }
      }
      std::sort(candidates.begin(), candidates.end(), [](const auto& a, const auto& b) {
        return a.first != b.first ? a.first > b.first : a.second < b.second;
      });
      if (candidates.size() > k) candidates.resize(k);
      std::vector<RetrievalNeighbor>& neighbors = result[first + q];
      neighbors.reserve(candidates.size());
      for (const auto& [units, image] : candidates) {
        neighbors.push_back({image, static_cast<float>(units * kGpuRetrievalScoreStep)});
      }
    }
  }
  if (stats != nullptr) {
    stats->resident_bytes = posting_offsets.bytes() + postings.bytes();
    stats->batches = starts.size() - 1;
    stats->tiles = num_tiles;
  }
  return result;
}

std::vector<std::vector<RetrievalNeighbor>> GpuAllTopK(const RetrievalIndexView& index, size_t k,
                                                       const GpuRetrievalConfig& config, GpuRetrievalStats* stats) {
  std::vector<uint32_t> all(index.num_images);
  for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<uint32_t>(i);
  return GpuTopK(index, all, k, config, stats);
}

}  // namespace cuda
}  // namespace cashash
