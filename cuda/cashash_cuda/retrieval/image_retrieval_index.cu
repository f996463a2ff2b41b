#include "cashash_cuda/retrieval/image_retrieval_index.h"

#include <cuda_runtime.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

#include "cashash/base/device_memory_error.h"
#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/device_memory.cuh"
#include "cashash_cuda/utils/device_scope.cuh"
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

// Adds the query's terms to the tile's scores: each warp takes 32 query
// words at a time (one coalesced load), then their posting lists one after
// the other, a lane per posting. A word's postings name distinct images,
// so the lanes of one atomicAdd never wait on each other's address.
__device__ __forceinline__ void AccumulateScores(const uint64_t* __restrict__ posting_offsets,
                                                 const RetrievalPosting* __restrict__ postings,
                                                 const RetrievalQueryWord* __restrict__ query_words,
                                                 uint64_t words_begin, uint64_t words_end, uint32_t tile_begin,
                                                 uint32_t size, uint32_t lane, uint32_t warp, uint32_t* scores) {
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
}

// The k-th largest nonzero score, a byte at a time from the top (radix
// select): after the four passes `threshold_prefix` is that score and
// `threshold_remaining` how many of the images holding it are kept. With
// k or fewer nonzero scores, every one is kept and `take_all_flag` is set.
// The three outputs are shared and start as 0, k and 0.
__device__ __forceinline__ void SelectThreshold(const uint32_t* scores, uint32_t size, uint32_t tid,
                                                uint32_t* histogram, uint32_t& threshold_prefix,
                                                uint32_t& threshold_remaining, uint32_t& take_all_flag) {
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
}

// Writes the scores above the threshold (or every nonzero score) to the
// slot, fewer than k, in any order; `written` (shared, 0) counts them.
__device__ __forceinline__ void WriteAboveThreshold(const uint32_t* scores, uint32_t size, uint32_t tid,
                                                    uint32_t tile_begin, bool take_all, uint32_t threshold,
                                                    uint32_t& written, uint32_t* slot_scores,
                                                    uint32_t* slot_images) {
  for (uint32_t i = tid; i < size; i += kThreads) {
    const uint32_t s = scores[i];
    if (s != 0 && (take_all || s > threshold)) {
      const uint32_t at = atomicAdd(&written, 1u);
      slot_scores[at] = s;
      slot_images[at] = tile_begin + i;
    }
  }
}

// Writes the `ties` lowest positions holding the threshold after the
// `above_count` written before them, found in position order (a
// block-wide count of the earlier ones), so the choice is the CPU's.
__device__ __forceinline__ void WriteTies(const uint32_t* scores, uint32_t size, uint32_t tid, uint32_t lane,
                                          uint32_t warp, uint32_t tile_begin, uint32_t threshold, uint32_t ties,
                                          uint32_t above_count, uint32_t* warp_counts, uint32_t* slot_scores,
                                          uint32_t* slot_images) {
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
}

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
  AccumulateScores(posting_offsets, postings, query_words, query_offsets[blockIdx.x], query_offsets[blockIdx.x + 1],
                   tile_begin, size, lane, warp, scores);
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

  SelectThreshold(scores, size, tid, histogram, threshold_prefix, threshold_remaining, take_all_flag);
  const bool take_all = take_all_flag != 0;
  const uint32_t threshold = threshold_prefix;
  const uint32_t ties = take_all ? 0 : threshold_remaining;

  uint32_t* slot_scores = out_scores + slot * k;
  uint32_t* slot_images = out_images + slot * k;
  WriteAboveThreshold(scores, size, tid, tile_begin, take_all, threshold, written, slot_scores, slot_images);
  __syncthreads();
  const uint32_t above_count = written;
  WriteTies(scores, size, tid, lane, warp, tile_begin, threshold, ties, above_count, warp_counts, slot_scores,
            slot_images);
  if (tid == 0) out_counts[slot] = above_count + ties;
}

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


// Throws for a query image outside the index, a missing GpuResources, or
// more images than 32-bit positions can name.
void CheckTopKArguments(const RetrievalIndexView& index, const std::vector<uint32_t>& query_images,
                        const GpuRetrievalConfig& config) {
  const size_t n = index.num_images;
  for (uint32_t image : query_images) {
    if (image >= n) {
      throw std::out_of_range("GpuTopK: image " + std::to_string(image) + " of " + std::to_string(n));
    }
  }
  if (config.resources == nullptr) throw std::invalid_argument("GpuTopK: no GpuResources");
  if (n > UINT32_MAX) throw std::invalid_argument("GpuTopK: more images than 32-bit positions");
}

// How one call splits the images: their number, images per tile, tiles,
// and how many results a tile keeps.
struct TilePlan {
  uint32_t num_images = 0;
  uint32_t tile_size = 0;
  uint32_t num_tiles = 1;
  uint32_t kept = 0;
};

// The postings and word offsets on the device, for the whole call.
struct ResidentIndex {
  DeviceBuffer posting_offsets, postings;
};

ResidentIndex UploadIndex(GpuResources* resources, const RetrievalIndexView& index, cudaStream_t stream) {
  ResidentIndex resident;
  resident.posting_offsets.Allocate(resources, (static_cast<size_t>(index.vocabulary_size) + 1) * sizeof(uint64_t),
                                    "retrieval word offsets");
  resident.postings.Allocate(resources, index.num_postings() * sizeof(RetrievalPosting), "retrieval postings");
  CUDA_CHECK(cudaMemcpyAsync(resident.posting_offsets.as<void>(), index.posting_offsets,
                             resident.posting_offsets.bytes(), cudaMemcpyHostToDevice, stream));
  if (resident.postings.bytes() > 0) {
    CUDA_CHECK(cudaMemcpyAsync(resident.postings.as<void>(), index.postings, resident.postings.bytes(),
                               cudaMemcpyHostToDevice, stream));
  }
  return resident;
}

// The device buffers of one batch of queries, sized for the largest batch.
struct BatchBuffers {
  DeviceBuffer words, offsets, images, scores, positions, counts;
};

// The most query words and the most queries of any batch.
void LargestBatch(const RetrievalIndexView& index, const std::vector<uint32_t>& query_images,
                  const std::vector<size_t>& starts, size_t* most_words, size_t* most_queries) {
  *most_words = 0;
  *most_queries = 0;
  for (size_t b = 0; b + 1 < starts.size(); ++b) {
    size_t words = 0;
    for (size_t q = starts[b]; q < starts[b + 1]; ++q) {
      words += index.query_offsets[query_images[q] + 1] - index.query_offsets[query_images[q]];
    }
    *most_words = std::max(*most_words, words);
    *most_queries = std::max(*most_queries, starts[b + 1] - starts[b]);
  }
}

// Splits the queries into batches and allocates `buffers` for the largest,
// halving the batches while the budget has no room for them. Returns the
// batches' starts (BatchStarts).
std::vector<size_t> AllocateBatches(GpuResources* resources, const RetrievalIndexView& index,
                                    const std::vector<uint32_t>& query_images, const TilePlan& plan,
                                    BatchBuffers* buffers) {
  const size_t result_bytes_per_query =
      static_cast<size_t>(plan.num_tiles) * (plan.kept * 2 * sizeof(uint32_t) + sizeof(uint32_t));
  size_t batch_bytes = kBatchBytes;
  for (;;) {
    std::vector<size_t> starts = BatchStarts(index, query_images, result_bytes_per_query, batch_bytes);
    size_t most_words = 0, most_queries = 0;
    LargestBatch(index, query_images, starts, &most_words, &most_queries);
    try {
      buffers->words.Allocate(resources, most_words * sizeof(RetrievalQueryWord), "retrieval query words");
      buffers->offsets.Allocate(resources, (most_queries + 1) * sizeof(uint64_t), "retrieval query offsets");
      buffers->images.Allocate(resources, most_queries * sizeof(uint32_t), "retrieval query images");
      const size_t slots = most_queries * plan.num_tiles;
      buffers->scores.Allocate(resources, slots * plan.kept * sizeof(uint32_t), "retrieval result scores");
      buffers->positions.Allocate(resources, slots * plan.kept * sizeof(uint32_t), "retrieval result images");
      buffers->counts.Allocate(resources, slots * sizeof(uint32_t), "retrieval result counts");
      return starts;
    } catch (const DeviceMemoryError&) {
      // One query per batch is the least there is.
      if (most_queries <= 1) throw;
      batch_bytes /= 2;
    }
  }
}

// The words of the batch's queries, with their offsets (from 0) in
// `offsets`. Consecutive images (every image's search) have their words in
// one piece of the index: returned from there, without a copy on the host;
// other batches' words are gathered into `gathered`.
const RetrievalQueryWord* GatherBatchWords(const RetrievalIndexView& index, const std::vector<uint32_t>& batch_images,
                                           std::vector<uint64_t>* offsets,
                                           std::vector<RetrievalQueryWord>* gathered) {
  offsets->assign(1, 0);
  gathered->clear();
  const size_t count = batch_images.size();
  bool consecutive = true;
  for (size_t q = 1; q < count && consecutive; ++q) consecutive = batch_images[q] == batch_images[0] + q;
  const RetrievalQueryWord* words = index.queries + index.query_offsets[batch_images.front()];
  for (uint32_t image : batch_images) {
    const size_t size = index.query_offsets[image + 1] - index.query_offsets[image];
    if (!consecutive) {
      gathered->insert(gathered->end(), index.queries + index.query_offsets[image],
                       index.queries + index.query_offsets[image + 1]);
    }
    offsets->push_back(offsets->back() + size);
  }
  if (!consecutive) words = gathered->data();
  return words;
}

// Every (query, tile) slot's list of one batch, on the host: slot s has
// counts[s] entries from s * kept in scores and images.
struct TileLists {
  std::vector<uint32_t> scores, images, counts;
};

// Sends the batch's queries, runs the kernel on each of its slots and
// brings the slots' lists back into `lists`; waits for the stream.
void RunBatch(const ResidentIndex& resident, const BatchBuffers& buffers, const TilePlan& plan,
              const std::vector<uint32_t>& batch_images, const std::vector<uint64_t>& offsets,
              const RetrievalQueryWord* words, cudaStream_t stream, TileLists* lists) {
  const size_t count = batch_images.size();
  if (offsets.back() > 0) {
    CUDA_CHECK(cudaMemcpyAsync(buffers.words.as<void>(), words, offsets.back() * sizeof(RetrievalQueryWord),
                               cudaMemcpyHostToDevice, stream));
  }
  CUDA_CHECK(cudaMemcpyAsync(buffers.offsets.as<void>(), offsets.data(), offsets.size() * sizeof(uint64_t),
                             cudaMemcpyHostToDevice, stream));
  CUDA_CHECK(cudaMemcpyAsync(buffers.images.as<void>(), batch_images.data(), count * sizeof(uint32_t),
                             cudaMemcpyHostToDevice, stream));
  const dim3 grid(static_cast<unsigned>(count), plan.num_tiles);
  RetrievalTopKKernel<<<grid, kThreads, plan.tile_size * sizeof(uint32_t), stream>>>(
      resident.posting_offsets.as<uint64_t>(), resident.postings.as<RetrievalPosting>(),
      buffers.offsets.as<uint64_t>(), buffers.words.as<RetrievalQueryWord>(), buffers.images.as<uint32_t>(),
      plan.num_images, plan.tile_size, plan.kept, buffers.scores.as<uint32_t>(), buffers.positions.as<uint32_t>(),
      buffers.counts.as<uint32_t>());
  CUDA_CHECK_LAUNCH();
  const size_t slots = count * plan.num_tiles;
  lists->scores.resize(slots * plan.kept);
  lists->images.resize(slots * plan.kept);
  lists->counts.resize(slots);
  CUDA_CHECK(cudaMemcpyAsync(lists->counts.data(), buffers.counts.as<void>(), slots * sizeof(uint32_t),
                             cudaMemcpyDeviceToHost, stream));
  CUDA_CHECK(cudaMemcpyAsync(lists->scores.data(), buffers.scores.as<void>(), slots * plan.kept * sizeof(uint32_t),
                             cudaMemcpyDeviceToHost, stream));
  CUDA_CHECK(cudaMemcpyAsync(lists->images.data(), buffers.positions.as<void>(),
                             slots * plan.kept * sizeof(uint32_t), cudaMemcpyDeviceToHost, stream));
  CUDA_CHECK(cudaStreamSynchronize(stream));
}

// Query q's best k of its tiles' lists, merged by the CPU's rule on the
// integer scores (two scores a unit apart may round to the same float).
// `candidates` is scratch space.
void MergeTileLists(const TileLists& lists, size_t q, const TilePlan& plan, size_t k,
                    std::vector<std::pair<uint32_t, uint32_t>>* candidates,
                    std::vector<RetrievalNeighbor>* neighbors) {
  candidates->clear();
  for (uint32_t tile = 0; tile < plan.num_tiles; ++tile) {
    const size_t slot = q * plan.num_tiles + tile;
    for (uint32_t c = 0; c < lists.counts[slot]; ++c) {
      candidates->emplace_back(lists.scores[slot * plan.kept + c], lists.images[slot * plan.kept + c]);
    }
  }
  std::sort(candidates->begin(), candidates->end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first > b.first : a.second < b.second;
  });
  if (candidates->size() > k) candidates->resize(k);
  neighbors->reserve(candidates->size());
  for (const auto& [units, image] : *candidates) {
    neighbors->push_back({image, static_cast<float>(units * kGpuRetrievalScoreStep)});
  }
}

}  // namespace

size_t GpuRetrievalResidentBytes(const RetrievalIndexView& index) {
  return (static_cast<size_t>(index.vocabulary_size) + 1) * sizeof(uint64_t) +
         index.num_postings() * sizeof(RetrievalPosting);
}

std::vector<std::vector<RetrievalNeighbor>> GpuTopK(const RetrievalIndexView& index,
                                                    const std::vector<uint32_t>& query_images, size_t k,
                                                    const GpuRetrievalConfig& config, GpuRetrievalStats* stats) {
  CheckTopKArguments(index, query_images, config);
  const size_t n = index.num_images;
  std::vector<std::vector<RetrievalNeighbor>> result(query_images.size());
  if (query_images.empty() || k == 0 || n < 2) return result;
  GpuResources* resources = config.resources;
  DeviceScope scope(resources->device());
  Stream stream;

  TilePlan plan;
  plan.num_images = static_cast<uint32_t>(n);
  plan.tile_size = ImagesPerTile(n, config.max_images_per_tile, &plan.num_tiles);
  // A tile keeps at most k, and never more than its images.
  plan.kept = static_cast<uint32_t>(std::min<size_t>(k, plan.tile_size));

  const ResidentIndex resident = UploadIndex(resources, index, stream.get());
  BatchBuffers buffers;
  const std::vector<size_t> starts = AllocateBatches(resources, index, query_images, plan, &buffers);

  std::vector<uint64_t> batch_offsets;
  std::vector<RetrievalQueryWord> batch_words;
  std::vector<uint32_t> batch_images;
  TileLists lists;
  std::vector<std::pair<uint32_t, uint32_t>> candidates;  // (units, image)
  for (size_t b = 0; b + 1 < starts.size(); ++b) {
    const size_t first = starts[b], count = starts[b + 1] - starts[b];
    batch_images.assign(query_images.begin() + static_cast<std::ptrdiff_t>(first),
                        query_images.begin() + static_cast<std::ptrdiff_t>(first + count));
    const RetrievalQueryWord* words = GatherBatchWords(index, batch_images, &batch_offsets, &batch_words);
    RunBatch(resident, buffers, plan, batch_images, batch_offsets, words, stream.get(), &lists);
    for (size_t q = 0; q < count; ++q) MergeTileLists(lists, q, plan, k, &candidates, &result[first + q]);
  }
  if (stats != nullptr) {
    stats->resident_bytes = resident.posting_offsets.bytes() + resident.postings.bytes();
    stats->batches = starts.size() - 1;
    stats->tiles = plan.num_tiles;
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
