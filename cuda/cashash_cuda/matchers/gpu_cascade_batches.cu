#include "cashash_cuda/matchers/gpu_cascade_batches.cuh"

#include <algorithm>
#include <limits>
#include <string>

#include "cashash/base/device_memory_error.h"
#include "cashash_cuda/matching/cascade_matcher_tiles.cuh"
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
// shared out in a second pass (BigBucketQueue): a few buckets of hundreds of
// features would otherwise keep one warp busy past the rest of the launch;
// matches are identical either way.
constexpr uint32_t kBigBucketFirstChunks = 4;

// Queue entries per batch: far more than the buckets past a few chunks
// (about one per table and pair at 16,384 features), 512 KiB.
constexpr uint32_t kBigBucketCapacity = 65536;

// Under a budget each of the two batch slots grows within a sixteenth of it
// (a batch of a single pair that needs more may take up to half of what the
// images leave): the rest is for the exact rematch's kernels and the
// verifier, which take their memory from the same owner (GpuResources).
constexpr size_t kSlotShareOfBudget = 16;

// The big-bucket queue of one slot as one typed block: the entries, then
// the counters the kernels share (cascade_matcher_tiles.cuh).
struct BigBucketBlock {
  uint2 entries[kBigBucketCapacity];
  unsigned long long header;  // count << 32 | chunks
  uint32_t cursor;            // the second pass's
  uint32_t overflow_base;     // where the second pass stops after an overflow
};

BigBucketQueue QueueOf(BigBucketBlock* block, int sm_count) {
  BigBucketQueue big;
  big.entries = block->entries;
  big.capacity = kBigBucketCapacity;
  big.header = &block->header;
  big.cursor = &block->cursor;
  big.overflow_base = &block->overflow_base;
  big.first_chunks = kBigBucketFirstChunks;
  big.warps = static_cast<unsigned>(sm_count) * 32u;
  return big;
}

MatchParams MatchParamsOf(const SiftMatchingOptions& sift_options, const CasHashOptions& options) {
  MatchParams params;
  params.num_tables = options.num_tables;
  params.bits_per_table = options.bits_per_table;
  params.tau = options.tau;
  params.top_k = options.top_k;
  params.max_ratio = static_cast<float>(sift_options.max_ratio);
  params.max_distance = static_cast<float>(sift_options.max_distance);
  for (int field = 0; field * options.bits_per_table < 64; ++field) {
    const int low = field * options.bits_per_table;
    const int high = std::min(low + options.bits_per_table, 64) - 1;
    params.field_low_bits |= uint64_t{1} << low;
    params.field_high_bits |= uint64_t{1} << high;
  }
  return params;
}

}  // namespace

GpuCascadeBatches::GpuCascadeBatches(const SiftMatchingOptions& sift_options, const CasHashOptions& options,
                                     int device, bool tiled, GpuResources* resources, GpuMemoryBooks* books)
    : sift_options_(sift_options),
      options_(options),
      device_(device),
      tiled_(tiled),
      list_capacity_(kCandidateListCapacity),
      resources_(resources),
      books_(books) {
  for (BatchSlot& slot : slots_) {
    slot.stream = CreateStageStream(StreamRole::kMatching);
    CUDA_CHECK(cudaEventCreateWithFlags(&slot.done, cudaEventDisableTiming));
  }
  grid_size_ = CascadeMatchGridSize(device_);
  CUDA_CHECK(cudaDeviceGetAttribute(&sm_count_, cudaDevAttrMultiProcessorCount, device_));
}

GpuCascadeBatches::~GpuCascadeBatches() {
  cudaSetDevice(device_);
  for (BatchSlot& slot : slots_) {
    if (slot.stream != nullptr) {
      cudaStreamSynchronize(slot.stream);
      cudaStreamDestroy(slot.stream);
    }
    if (slot.done != nullptr) cudaEventDestroy(slot.done);
  }
}

void GpuCascadeBatches::Match(const std::vector<PairTask>& tasks, const std::vector<size_t>& pair_of_task,
                              const GpuEpipolarGuides* guides, std::vector<FeatureMatches>* results) {
  int next_slot = 0;
  size_t start = 0;
  while (start < tasks.size()) {
    BatchSlot& slot = slots_[next_slot];
    next_slot ^= 1;
    if (slot.busy) Harvest(&slot, results);
    const size_t end = BatchEnd(tasks, start);
    Launch(&slot, tasks, pair_of_task, guides, start, end);
    start = end;
  }
  for (int k = 0; k < 2; ++k) {
    BatchSlot& slot = slots_[next_slot];
    next_slot ^= 1;
    if (slot.busy) Harvest(&slot, results);
  }
}

// Bytes of the candidate lists of `rows` features (tiled kernels).
size_t GpuCascadeBatches::ListBytes(size_t rows) const {
  return tiled_ ? rows * (list_capacity_ + 1) * sizeof(uint32_t) : 0;
}

// Device bytes of a batch slot sized for `tasks` pairs, `queries` forward
// queries and `rows` list rows (features of both sides).
size_t GpuCascadeBatches::SlotBytes(size_t tasks, size_t queries, size_t rows) const {
  return tasks * sizeof(PairTask) + queries * sizeof(int32_t) + ListBytes(rows) + 512;
}

// End of the batch starting at `start`: bounded by kMaxBatch* and by the
// memory budget left for the two slots: a batch grows within its share
// (kSlotShareOfBudget) and takes at least one pair where that pair fits
// half of what the images leave.
size_t GpuCascadeBatches::BatchEnd(const std::vector<PairTask>& tasks, size_t start) const {
  size_t free_for_slots = std::numeric_limits<size_t>::max();
  size_t most_for_one_pair = std::numeric_limits<size_t>::max();
  if (books_->capped()) {
    const size_t budget = books_->budget();
    size_t slots_now = 0;
    for (const BatchSlot& s : slots_) slots_now += SlotBytes(s.task_capacity, s.query_capacity, s.row_capacity);
    const size_t images = books_->used() - slots_now;
    free_for_slots = budget / kSlotShareOfBudget;
    most_for_one_pair = budget > images ? (budget - images) / 2 : 0;
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

// Grows the slot's buffers to hold `num_tasks` pairs, `queries` queries and
// `rows` list rows.
void GpuCascadeBatches::EnsureCapacity(BatchSlot* slot, size_t num_tasks, size_t queries, size_t rows) {
  if (num_tasks <= slot->task_capacity && queries <= slot->query_capacity && rows <= slot->row_capacity) return;
  const size_t new_tasks = std::max(num_tasks, slot->task_capacity);
  const size_t new_queries = std::max(queries, slot->query_capacity);
  const size_t new_rows = std::max(rows, slot->row_capacity);
  books_->Release(SlotBytes(slot->task_capacity, slot->query_capacity, slot->row_capacity));
  slot->tasks.Release();
  slot->best.Release();
  slot->list_keys.Release();
  slot->list_counts.Release();
  slot->task_capacity = slot->query_capacity = slot->row_capacity = 0;
  books_->Reserve(SlotBytes(new_tasks, new_queries, new_rows), "matching scratch");
  slot->tasks.Allocate(resources_, new_tasks * sizeof(PairTask), "pair tasks");
  slot->best.Allocate(resources_, new_queries * sizeof(int32_t), "match results");
  if (tiled_ && new_rows > 0) {
    slot->list_keys.Allocate(resources_, new_rows * list_capacity_ * sizeof(uint32_t), "candidate lists");
    slot->list_counts.Allocate(resources_, new_rows * sizeof(uint32_t), "candidate list counts");
  }
  if (slot->cursor.bytes() == 0) slot->cursor.Allocate(resources_, 256, "match cursor");
  slot->host_tasks.Allocate(resources_, new_tasks * sizeof(PairTask), "pair tasks");
  slot->segments.Allocate(resources_, new_tasks * sizeof(MatchSegment), "match segments");
  slot->out.Allocate(resources_, new_queries * sizeof(uint2), "matches");
  slot->task_capacity = new_tasks;
  slot->query_capacity = new_queries;
  slot->row_capacity = new_rows;
}

// The guides of tasks [start, end) to the slot's device buffer, on its
// stream.
void GpuCascadeBatches::StageGuides(BatchSlot* slot, const GpuEpipolarGuides& guides, size_t start, size_t end) {
  const size_t num_tasks = end - start;
  if (slot->guide_capacity < num_tasks) {
    books_->Release(slot->guides.bytes());
    slot->guides.Release();
    slot->guide_capacity = 0;
    books_->Reserve(num_tasks * sizeof(EpipolarGuideDevice), "epipolar guides");
    slot->guides.Allocate(resources_, num_tasks * sizeof(EpipolarGuideDevice), "epipolar guides");
    slot->host_guides.Allocate(resources_, num_tasks * sizeof(EpipolarGuideDevice), "epipolar guides");
    slot->guide_capacity = num_tasks;
  }
  EpipolarGuideDevice* staged = slot->host_guides.host<EpipolarGuideDevice>();
  std::copy(guides.of_tasks().begin() + start, guides.of_tasks().begin() + end, staged);
  CUDA_CHECK(cudaMemcpyAsync(slot->guides.as<EpipolarGuideDevice>(), staged, num_tasks * sizeof(EpipolarGuideDevice),
                             cudaMemcpyHostToDevice, slot->stream));
}

// A batch's staging (task offsets, items, rows), uploads, memsets and
// kernels, enqueued in this order on slot->stream, the later launches
// reading the sizes summed first.
void GpuCascadeBatches::Launch(BatchSlot* slot, const std::vector<PairTask>& all_tasks,
                               const std::vector<size_t>& pair_of_task, const GpuEpipolarGuides* guides,
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
  CUDA_CHECK(cudaMemcpyAsync(slot->tasks.as<PairTask>(), staged, num_tasks * sizeof(PairTask), cudaMemcpyHostToDevice,
                             slot->stream));
  if (guides != nullptr) StageGuides(slot, *guides, start, end);
  CUDA_CHECK(cudaMemsetAsync(slot->cursor.as<uint32_t>(), 0, sizeof(uint32_t), slot->stream));
  const MatchParams params = MatchParamsOf(sift_options_, options_);
  const PairTask* tasks = slot->tasks.as<PairTask>();
  const int n = static_cast<int>(num_tasks);
  const bool cross_check = sift_options_.cross_check;
  int32_t* best = slot->best.as<int32_t>();
  const EpipolarGuideDevice* guide_of_task = guides ? slot->guides.as<EpipolarGuideDevice>() : nullptr;
  if (tiled_) {
    CandidateLists lists;
    lists.keys = slot->list_keys.as<uint32_t>();
    lists.counts = slot->list_counts.as<uint32_t>();
    lists.capacity = list_capacity_;
    CUDA_CHECK(cudaMemsetAsync(lists.counts, 0, rows * sizeof(uint32_t), slot->stream));
    if (slot->big_buckets.bytes() == 0) {
      slot->big_buckets.Allocate(resources_, sizeof(BigBucketBlock), "big-bucket queue");
    }
    LaunchCascadeTiles(tasks, n, params, lists, slot->stream, QueueOf(slot->big_buckets.as<BigBucketBlock>(), sm_count_));
    if (guides != nullptr) {
      LaunchCascadeSelectGuided(tasks, n, items, params, lists, guide_of_task, guides->points(),
                                guides->max_distance(), cross_check, grid_size_, best, slot->stream);
    } else {
      LaunchCascadeSelect(tasks, n, items, params, lists, cross_check, grid_size_, best, slot->stream);
    }
  } else if (guides != nullptr) {
    LaunchCascadeMatchGuided(tasks, n, items, params, guide_of_task, guides->points(), guides->max_distance(),
                             cross_check, grid_size_, best, slot->stream);
  } else {
    LaunchCascadeMatch(tasks, n, items, params, cross_check, grid_size_, best, slot->stream);
  }
  LaunchCompactMatches(tasks, n, best, slot->out.device<uint2>(), slot->segments.device<MatchSegment>(),
                       slot->cursor.as<uint32_t>(), slot->stream);
  CUDA_CHECK(cudaEventRecord(slot->done, slot->stream));
  slot->busy = true;
}

void GpuCascadeBatches::Harvest(BatchSlot* slot, std::vector<FeatureMatches>* results) {
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

}  // namespace cuda
}  // namespace cashash
