// Kernels of cascade_matcher.cuh.
//
// Per query (one warp): the lanes stream the query's buckets of all tables
// of the target image 32 entries at a time (BucketEntry rows are contiguous:
// two coalesced 16-byte loads per lane, one 32-byte sector), compute the
// 128-bit Hamming distance with popcount, drop it if > tau or not better than
// the current k-th key, drop duplicates (a candidate counts only in the first
// table where it shares the query's bucket: its signature tells which), and
// queue the survivors; queued keys (distance << 24 | feature) are merged into
// a warp-resident sorted list 32 at a time with a bitonic sort. The k best
// keys then get exact integer dot products (dp4a, 8 lanes per candidate),
// and best / second best decide with COLMAP's ratio and distance rule. Ties
// follow cascade_hashing.h: keys are unique and ordered by (distance, index);
// dots by (dot descending, index ascending).
//
// Over 600 lines because it is one kernel family (match, select, guided, compact)
// built from the same inlined device helpers (QueryRanking, DecideFromRanked, ...).
#include "cashash_cuda/matching/cascade_matcher.cuh"

#include "cashash/matching/cascade_hashing.h"
#include "cashash/matching/epipolar_band.h"
#include "cashash_cuda/matching/cascade_matcher_tiles.cuh"
#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/warp_primitives.cuh"

namespace cashash {
namespace cuda {
namespace {

constexpr int kThreads = 256;
// 4 blocks of 256 threads per SM: at most 64 registers, 32 warps per SM.
constexpr int kMinBlocksPerSm = 4;
constexpr uint32_t kIndexMask = kMaxGpuFeatures - 1;
constexpr float kDotNormalisation = 1.0f / (512.0f * 512.0f);

__device__ __forceinline__ float DotToAngle(int dot) {
  return acosf(fminf(kDotNormalisation * static_cast<float>(dot), 1.0f));
}

// Same rule as AcceptSiftMatch (descriptor_distance.h).
__device__ __forceinline__ bool Accept(int best_dot, int second_dot, float max_ratio, float max_distance) {
  const float best_angle = DotToAngle(best_dot);
  if (best_angle > max_distance) return false;
  return best_angle < max_ratio * DotToAngle(second_dot);
}

__device__ __forceinline__ int FindTask(const PairTask* tasks, int num_tasks, uint32_t item) {
  int lo = 0, hi = num_tasks - 1;
  while (lo < hi) {
    const int mid = (lo + hi + 1) / 2;
    if (tasks[mid].item_begin <= item) lo = mid;
    else hi = mid - 1;
  }
  return lo;
}

__device__ __forceinline__ uint32_t Dot16(uint4 a, uint4 b) {
  uint32_t s = __dp4a(a.x, b.x, 0u);
  s = __dp4a(a.y, b.y, s);
  s = __dp4a(a.z, b.z, s);
  return __dp4a(a.w, b.w, s);
}

// Per-warp shared scratch of one query. Tables with an empty bucket are
// left out, so that "slot" s is the s-th non-empty bucket in stream order.
struct WarpScratch {
  uint32_t base[kMaxGpuTables];   // entry index of stream position p in slot s: base[s] + p
  uint32_t start[kMaxGpuTables];  // stream position where slot s begins
  // (both are read back into lane s: the compaction goes through here)
  uint32_t pending[64 + 1];       // survivors not yet merged into the ranked list; [64]: discard slot
};

// Capacity of WarpScratch::pending: two chunks' survivors always fit.
constexpr int kPendingCapacity = 64;

// Up to this many pending survivors are inserted one by one (~12
// instructions each); more are sorted and merged (~110 instructions).
constexpr int kSerialMergeMax = 6;

// Candidates of one query ranked by key (distance << 24 | feature). The
// chunks append their survivors to a shared buffer; 32 or more pending (or
// the end of the stream) are sorted and merged into the warp-resident list
// 32 at a time, so the first chunks of a query, where nearly every candidate
// within tau survives, cost one merge instead of one insertion per survivor.
struct QueryRanking {
  WarpSortedList ranked;
  // Keys below `limit` can still enter the top k: (tau + 1) << 24 (every key
  // within tau) until k keys are ranked, then the k-th ranked key. One
  // compare thus does both the tau and the rank test. Only ever decreases.
  uint32_t limit;
  int num_pending = 0;  // same in every lane
  bool ranked_empty = true;  // false once anything may have been ranked

  __device__ __forceinline__ explicit QueryRanking(uint32_t tau) : limit((min(tau, 128u) + 1u) << 24) {}
  __device__ __forceinline__ void Merge(const uint32_t* pending, int top_k) {
    __syncwarp();
    for (int base = 0; base < num_pending; base += 32) {
      const int batch = min(32, num_pending - base);
      if (batch <= kSerialMergeMax) {
        for (int i = 0; i < batch; ++i) {
          const uint32_t k = pending[base + i];
          if (k < limit) {
            ranked.Insert(k);
            limit = min(limit, ranked.At(top_k - 1));
          }
        }
      } else {
        const uint32_t v =
            LaneId() < static_cast<unsigned>(batch) ? pending[base + LaneId()] : WarpSortedList::kEmptyKey;
        const uint32_t sorted = WarpBitonicSort(v);
        // Most queries merge once: into an empty list, which is a copy.
        if (ranked_empty) {
          ranked.key = sorted;
        } else {
          ranked.MergeSorted(sorted);
        }
        limit = min(limit, ranked.At(top_k - 1));
      }
      ranked_empty = false;
    }
    num_pending = 0;
    __syncwarp();
  }

  // Queues this lane's keys of two chunks (kEmptyKey: none); merges once 32
  // or more are pending, so that the k-th key tightens early.
  __device__ __forceinline__ void Add(uint32_t key0, uint32_t key1, uint32_t* pending, int top_k) {
    const unsigned ballot0 = __ballot_sync(kFullWarpMask, key0 != WarpSortedList::kEmptyKey);
    const unsigned ballot1 = __ballot_sync(kFullWarpMask, key1 != WarpSortedList::kEmptyKey);
    const int count0 = __popc(ballot0), count = count0 + __popc(ballot1);
    if (count == 0) return;
    if (num_pending + count > kPendingCapacity) Merge(pending, top_k);
    // Lanes without a key store into the discard slot: no branches.
    const unsigned below = LaneMaskLt();
    pending[key0 != WarpSortedList::kEmptyKey ? num_pending + __popc(ballot0 & below) : kPendingCapacity] = key0;
    pending[key1 != WarpSortedList::kEmptyKey ? num_pending + count0 + __popc(ballot1 & below) : kPendingCapacity] =
        key1;
    num_pending += count;
    if (num_pending >= 32) Merge(pending, top_k);
  }
};

// Where the entries of one chunk of 32 stream positions [first, first + 32)
// are: lane L gets the entry index of position first + L. `slot_before` is
// the slot of position first - 1 (~0u before the stream) and moves on to the
// slot of position first + 31. The slots starting inside the chunk are one
// OR-reduction of bits, so no lane searches the table starts.
// Lane s holds my_start / my_base of slot s. Lanes past the end of the
// stream get the last entry (in the last slot), so that every lane loads
// unconditionally from a valid address.
__device__ __forceinline__ uint32_t ChunkEntryIndex(uint32_t my_start, uint32_t my_base, uint32_t first, uint32_t total,
                                                   uint32_t& slot_before) {
  const uint32_t rel = my_start - first;
  const unsigned starts = WarpReduceOr(rel < 32 ? 1u << rel : 0u);
  const uint32_t slot = slot_before + __popc(starts & LaneMaskLe());
  slot_before += __popc(starts);
  return __shfl_sync(kFullWarpMask, my_base, slot) + min(first + LaneId(), total - 1);
}

// Ranking key of one bucket entry, or kEmptyKey when it is not below
// `limit` (beyond tau, or not better than the k-th ranked key), or a
// duplicate: a candidate counts only in the
// first table where it shares the query's bucket, i.e. a duplicate has a zero
// b-bit field of (signature diff) below its own table. Fields from its table
// up get their top bit set, then the borrow test finds a zero field exactly
// (a borrow can only start at a zero field).
__device__ __forceinline__ uint32_t EntryKey(uint4 c, uint4 s, bool valid, uint64_t signature, ulonglong2 code,
                                             uint32_t limit, const MatchParams& params) {
  const uint32_t distance = __popc(uint32_t(code.x) ^ c.x) + __popc(uint32_t(code.x >> 32) ^ c.y) +
                            __popc(uint32_t(code.y) ^ c.z) + __popc(uint32_t(code.y >> 32) ^ c.w);
  const uint32_t candidate = (distance << 24) | s.z;
  uint32_t key = WarpSortedList::kEmptyKey;
  if (valid && candidate < limit) {
    const uint64_t diff = signature ^ (uint64_t(s.y) << 32 | s.x);
    const uint64_t below = (uint64_t{1} << s.w) - 1;
    const uint64_t v = (diff & below) | (params.field_high_bits & ~below);
    const bool duplicate = ((v - params.field_low_bits) & ~v & params.field_high_bits) != 0;
    if (!duplicate) key = candidate;
  }
  return key;
}

// The query's buckets of all tables in `target` as one stream of `total`
// entries: lane s holds where slot s (the s-th non-empty bucket) starts in
// the stream and in the entry array (see ChunkEntryIndex).
struct BucketStream {
  uint32_t total;
  uint32_t my_start;
  uint32_t my_base;
};

__device__ __forceinline__ BucketStream OpenBucketStream(uint64_t signature, const DeviceImageView& target,
                                                         const MatchParams& params, WarpScratch& scratch) {
  const unsigned lane = LaneId();
  const int num_tables = params.num_tables;
  const int bits = params.bits_per_table;
  const uint32_t buckets = 1u << bits;
  const uint64_t bucket_mask = buckets - 1;
  const uint32_t n = target.num_features;
  // Lane t < num_tables reads the bucket of table t; a scan places them.
  uint32_t size = 0, begin = 0;
  if (static_cast<int>(lane) < num_tables) {
    const uint32_t bucket = static_cast<uint32_t>((signature >> (lane * bits)) & bucket_mask);
    const uint32_t* offsets = target.offsets + lane * (buckets + 1) + bucket;
    begin = offsets[0];
    size = offsets[1] - begin;
  }
  uint32_t inclusive = size;
  for (int d = 1; d < num_tables; d <<= 1) {
    const uint32_t o = __shfl_up_sync(kFullWarpMask, inclusive, d);
    if (lane >= static_cast<unsigned>(d)) inclusive += o;
  }
  BucketStream stream;
  stream.total = __shfl_sync(kFullWarpMask, inclusive, num_tables - 1);
  const unsigned nonempty = __ballot_sync(kFullWarpMask, size != 0);
  __syncwarp();  // the previous query's reads of the scratch are done
  if (size != 0) {
    const uint32_t slot = __popc(nonempty & LaneMaskLt());
    scratch.base[slot] = lane * n + begin - (inclusive - size);
    scratch.start[slot] = inclusive - size;
  }
  __syncwarp();
  const bool has_slot = lane < static_cast<unsigned>(__popc(nonempty));
  stream.my_start = has_slot ? scratch.start[lane] : 0xffffffffu;
  stream.my_base = has_slot ? scratch.base[lane] : 0u;
  return stream;
}

// Step 5b of cascade_hashing.h: the kBeyondTauCandidates (two) nearest
// distinct candidates beyond tau, as keys (distance << 24 | feature) in
// ascending order, kEmptyKey where there are fewer; same in every lane.
// One more pass over the query's buckets, taken only for accepted matches
// from thin lists.
__device__ void NearestBeyondTau(const DeviceImageView& query, uint32_t q, const DeviceImageView& target,
                                 const MatchParams& params, WarpScratch& scratch, uint32_t* first,
                                 uint32_t* second) {
  static_assert(kBeyondTauCandidates == 2, "two nearest candidates beyond tau are tracked");
  const BucketStream stream = OpenBucketStream(query.signatures[q], target, params, scratch);
  const ulonglong2 code = query.codes[q];
  const uint32_t tau = static_cast<uint32_t>(min(params.tau, 128));
  uint32_t min1 = WarpSortedList::kEmptyKey, min2 = WarpSortedList::kEmptyKey;
  uint32_t slot_before = ~0u;
  for (uint32_t chunk = 0; chunk < stream.total; chunk += 32) {
    const uint4* entry = reinterpret_cast<const uint4*>(
        target.entries + ChunkEntryIndex(stream.my_start, stream.my_base, chunk, stream.total, slot_before));
    const uint4 c = __ldg(entry), meta = __ldg(entry + 1);
    const uint32_t distance = __popc(uint32_t(code.x) ^ c.x) + __popc(uint32_t(code.x >> 32) ^ c.y) +
                              __popc(uint32_t(code.y) ^ c.z) + __popc(uint32_t(code.y >> 32) ^ c.w);
    const uint32_t key = distance << 24 | meta.z;
    if (chunk + LaneId() < stream.total && distance > tau && key < min2 && key != min1) {
      if (key < min1) {
        min2 = min1;
        min1 = key;
      } else {
        min2 = key;
      }
    }
  }
  // A feature sharing several tables' buckets can be the min of several
  // lanes: those lanes offer their own second instead.
  *first = WarpReduceMin(min1);
  *second = WarpReduceMin(min1 == *first ? min2 : min1);
}

// Exact dot product of the query row with target feature f (every lane).
__device__ __forceinline__ int WarpDot(const uint8_t* query_row, const uint8_t* target_row) {
  const uint32_t a = reinterpret_cast<const uint32_t*>(query_row)[LaneId()];
  const uint32_t b = reinterpret_cast<const uint32_t*>(target_row)[LaneId()];
  return static_cast<int>(WarpReduceAdd(__dp4a(a, b, 0u)));
}

// Exact dot products of the ranked candidates, then best / second best and
// COLMAP's rule: the accepted match of feature q of `query`, or -1 (the same
// value in every lane). Unguided queries decide thin lists again with the
// nearest candidates beyond tau (step 5b of cascade_hashing.h).
template <bool kUnguided>
__device__ __forceinline__ int DecideFromRanked(const DeviceImageView& query, uint32_t q,
                                                const DeviceImageView& target, const WarpSortedList& ranked,
                                                const MatchParams& params, WarpScratch& scratch) {
  const unsigned lane = LaneId();

  // Exact dot products of the ranked candidates: 8 per pass, 4 lanes of 32
  // bytes each (two 16-byte loads per lane, 8 dp4a, a 4-lane sum). Passes go
  // two at a time with all four loads issued first: the descriptors are a
  // round trip to L2, and top_k 16 needs exactly two passes.
  const int count = min(__popc(__ballot_sync(kFullWarpMask, ranked.key != WarpSortedList::kEmptyKey)), params.top_k);
  if (count == 0) return -1;
  const unsigned part = lane & 3, group = lane >> 2;
  const uint4* mine = reinterpret_cast<const uint4*>(query.descriptors + size_t(q) * 128) + 2 * part;
  const uint4 mine0 = mine[0], mine1 = mine[1];
  int my_dot = 0;
  for (int first = 0; first < count; first += 16) {
    uint4 other[2][2];
#pragma unroll
    for (int h = 0; h < 2; ++h) {
      const int j = first + 8 * h + static_cast<int>(group);
      const uint32_t key = ranked.At(min(j, 31));
      other[h][0] = other[h][1] = make_uint4(0, 0, 0, 0);
      if (j < count) {
        const uint4* row = reinterpret_cast<const uint4*>(target.descriptors + size_t(key & kIndexMask) * 128) + 2 * part;
        other[h][0] = row[0];
        other[h][1] = row[1];
      }
    }
#pragma unroll
    for (int h = 0; h < 2; ++h) {
      const int dot = GroupSum<4>(static_cast<int>(Dot16(mine0, other[h][0]) + Dot16(mine1, other[h][1])));
      // Lane L in [first + 8h, first + 8h + 8) takes the dot of candidate L.
      const int rel = static_cast<int>(lane) - first - 8 * h;
      const int got = __shfl_sync(kFullWarpMask, dot, (rel * 4) & 31);
      if (rel >= 0 && rel < 8) my_dot = got;
    }
  }
  // Best by (dot descending, index ascending), second = largest dot of the
  // others (0 when none): three single-instruction warp reductions. Dots of
  // uint8 vectors are >= 0.
  const bool valid = static_cast<int>(lane) < count;
  const uint32_t dot = valid ? static_cast<uint32_t>(my_dot) : 0u;
  const uint32_t index = ranked.key & kIndexMask;
  const uint32_t best_dot = WarpReduceMax(dot);
  if (best_dot == 0) return -1;
  const uint32_t best_index = WarpReduceMin(valid && dot == best_dot ? index : 0xffffffffu);
  const uint32_t second_dot = WarpReduceMax(valid && index != best_index ? dot : 0u);
  if (!Accept(static_cast<int>(best_dot), static_cast<int>(second_dot), params.max_ratio, params.max_distance)) {
    return -1;
  }
  if (!kUnguided || count >= kThinListSize) return static_cast<int>(best_index);
  // Step 5b: (dot descending, index ascending) over the ranked and the
  // nearest candidates beyond tau.
  uint32_t beyond[kBeyondTauCandidates];
  NearestBeyondTau(query, q, target, params, scratch, &beyond[0], &beyond[1]);
  int best = static_cast<int>(best_dot), second = static_cast<int>(second_dot);
  uint32_t best_f = best_index;
  const uint8_t* query_row = query.descriptors + size_t(q) * 128;
  for (uint32_t key : beyond) {
    if (key == WarpSortedList::kEmptyKey) continue;
    const uint32_t f = key & kIndexMask;
    const int d = WarpDot(query_row, target.descriptors + size_t(f) * 128);
    if (d > best || (d == best && f < best_f)) {
      second = max(second, best);
      best = d;
      best_f = f;
    } else {
      second = max(second, d);
    }
  }
  if (!Accept(best, second, params.max_ratio, params.max_distance)) return -1;
  return static_cast<int>(best_f);
}

// Candidate filters of MatchQuery / SelectQuery: every candidate
// (exhaustive matching) or those within the query's epipolar band (guided
// matching). Filter(key) gives key or kEmptyKey.
struct NoBand {
  static constexpr bool kUnguided = true;
  __device__ __forceinline__ uint32_t Filter(uint32_t key) const { return key; }
};

struct InBand {
  static constexpr bool kUnguided = false;
  EpipolarLine line;
  const float2* target_points;
  double max_distance;
  __device__ __forceinline__ uint32_t Filter(uint32_t key) const {
    if (key == WarpSortedList::kEmptyKey) return key;
    const float2 p = target_points[key & kIndexMask];
    return line.Contains(p.x, p.y, max_distance) ? key : WarpSortedList::kEmptyKey;
  }
};

// Accepted best match in `target` of feature q of `query`, or -1 (the same
// value in every lane).
//
// The buckets of all tables form one stream of candidates, processed two
// chunks of 32 (one entry per lane) at a time with all four loads issued
// before either chunk is ranked.
template <class Band>
__device__ int MatchQuery(const DeviceImageView& query, uint32_t q, const DeviceImageView& target,
                          const MatchParams& params, WarpScratch& scratch, const Band& band) {
  const unsigned lane = LaneId();
  const uint32_t tau = static_cast<uint32_t>(params.tau);
  const uint64_t signature = query.signatures[q];
  const ulonglong2 code = query.codes[q];
  const BucketEntry* entries = target.entries;
  const BucketStream stream = OpenBucketStream(signature, target, params, scratch);
  const uint32_t total = stream.total, my_start = stream.my_start, my_base = stream.my_base;

  QueryRanking ranking(tau);
  uint32_t slot_before = ~0u;
  for (uint32_t first = 0; first < total; first += 64) {
    const uint32_t pos0 = first + lane, pos1 = pos0 + 32;
    const uint4* entry0 = reinterpret_cast<const uint4*>(entries + ChunkEntryIndex(my_start, my_base, first, total,
                                                                                   slot_before));
    const uint4 c0 = __ldg(entry0), s0 = __ldg(entry0 + 1);
    // The second chunk of the last step is empty about half of the time:
    // skipped as a whole (a warp-uniform branch). Its loads still go out
    // before the first chunk is ranked.
    uint32_t key1 = WarpSortedList::kEmptyKey;
    if (first + 32 < total) {
      const uint4* entry1 = reinterpret_cast<const uint4*>(
          entries + ChunkEntryIndex(my_start, my_base, first + 32, total, slot_before));
      const uint4 c1 = __ldg(entry1), s1 = __ldg(entry1 + 1);
      key1 = band.Filter(EntryKey(c1, s1, pos1 < total, signature, code, ranking.limit, params));
    }
    ranking.Add(band.Filter(EntryKey(c0, s0, pos0 < total, signature, code, ranking.limit, params)), key1,
                scratch.pending, params.top_k);
  }
  if (ranking.num_pending > 0) ranking.Merge(scratch.pending, params.top_k);
  return DecideFromRanked<Band::kUnguided>(query, q, target, ranking.ranked, params, scratch);
}

// The same answer from the query's candidate list (list row `row`): every
// candidate within tau, de-duplicated already, in no particular order. The
// keys are ranked exactly as in MatchQuery; a list that overflowed (more
// candidates than it holds) is answered by MatchQuery itself.
template <class Band>
__device__ int SelectQuery(const DeviceImageView& query, uint32_t q, size_t row, const DeviceImageView& target,
                           const CandidateLists& lists, const MatchParams& params, WarpScratch& scratch,
                           const Band& band) {
  const unsigned lane = LaneId();
  const uint32_t total = lists.counts[row];
  if (total > static_cast<uint32_t>(lists.capacity)) return MatchQuery(query, q, target, params, scratch, band);
  const uint32_t* keys = lists.keys + row * lists.capacity;
  QueryRanking ranking(static_cast<uint32_t>(params.tau));
  __syncwarp();  // the previous query's reads of the scratch are done
  for (uint32_t first = 0; first < total; first += 64) {
    const uint32_t pos0 = first + lane, pos1 = pos0 + 32;
    uint32_t key0 = pos0 < total ? __ldg(keys + pos0) : WarpSortedList::kEmptyKey;
    uint32_t key1 = pos1 < total ? __ldg(keys + pos1) : WarpSortedList::kEmptyKey;
    if (key0 >= ranking.limit) key0 = WarpSortedList::kEmptyKey;
    if (key1 >= ranking.limit) key1 = WarpSortedList::kEmptyKey;
    ranking.Add(band.Filter(key0), band.Filter(key1), scratch.pending, params.top_k);
  }
  if (ranking.num_pending > 0) ranking.Merge(scratch.pending, params.top_k);
  return DecideFromRanked<Band::kUnguided>(query, q, target, ranking.ranked, params, scratch);
}

// How the match kernel answers one query: straight from the bucket tables,
// or from the candidate lists of the tile kernel.
struct DirectQuery {
  __device__ __forceinline__ int operator()(const PairTask* task, bool reverse, uint32_t q,
                                            const MatchParams& params, WarpScratch& scratch) const {
    return MatchQuery(reverse ? task->b : task->a, q, reverse ? task->a : task->b, params, scratch, NoBand{});
  }
};

struct ListQuery {
  CandidateLists lists;
  __device__ __forceinline__ int operator()(const PairTask* task, bool reverse, uint32_t q,
                                            const MatchParams& params, WarpScratch& scratch) const {
    const size_t row = size_t(task->list_offset) + (reverse ? task->a.num_features : 0u) + q;
    return SelectQuery(reverse ? task->b : task->a, q, row, reverse ? task->a : task->b, lists, params, scratch,
                       NoBand{});
  }
};

// The band of query q of the task (forward: a's feature, line F x in b;
// reverse: b's feature, line F^T x in a).
struct Guidance {
  const PairTask* tasks;
  const EpipolarGuideDevice* guides;
  const float2* points;
  double max_distance;
  __device__ __forceinline__ InBand Band(const PairTask* task, bool reverse, uint32_t q) const {
    const EpipolarGuideDevice& guide = guides[task - tasks];
    const float2* points_a = points + guide.points_a;
    const float2* points_b = points + guide.points_b;
    InBand band;
    if (!reverse) {
      const float2 x = points_a[q];
      band.line = LineInSecondImage(guide.F, x.x, x.y);
      band.target_points = points_b;
    } else {
      const float2 x = points_b[q];
      band.line = LineInFirstImage(guide.F, x.x, x.y);
      band.target_points = points_a;
    }
    band.max_distance = max_distance;
    return band;
  }
};

struct GuidedDirectQuery {
  Guidance guidance;
  __device__ __forceinline__ int operator()(const PairTask* task, bool reverse, uint32_t q,
                                            const MatchParams& params, WarpScratch& scratch) const {
    return MatchQuery(reverse ? task->b : task->a, q, reverse ? task->a : task->b, params, scratch,
                      guidance.Band(task, reverse, q));
  }
};

struct GuidedListQuery {
  CandidateLists lists;
  Guidance guidance;
  __device__ __forceinline__ int operator()(const PairTask* task, bool reverse, uint32_t q,
                                            const MatchParams& params, WarpScratch& scratch) const {
    const size_t row = size_t(task->list_offset) + (reverse ? task->a.num_features : 0u) + q;
    return SelectQuery(reverse ? task->b : task->a, q, row, reverse ? task->a : task->b, lists, params, scratch,
                       guidance.Band(task, reverse, q));
  }
};

// best[i] = match of a's feature i in b. With kCrossCheck, a forward match j
// is re-queried right away (j of b against a, same warp) and dropped unless
// the answer is i: one launch, and the reverse work spreads over all warps
// with the forward work instead of waiting in a second pass.
template <bool kCrossCheck, class Query>
__global__ void __launch_bounds__(kThreads, kMinBlocksPerSm) CascadeMatchKernel(const PairTask* tasks, int num_tasks,
                                                                              uint32_t total_items, MatchParams params,
                                                                              Query query, int32_t* best) {
  __shared__ WarpScratch warp_scratch[kThreads / 32];
  WarpScratch& scratch = warp_scratch[threadIdx.x >> 5];
  const unsigned lane = LaneId();
  const uint32_t warps = gridDim.x * (kThreads / 32);
  for (uint32_t item = blockIdx.x * (kThreads / 32) + (threadIdx.x >> 5); item < total_items; item += warps) {
    // The image views stay in (cached) global memory: a copy of both would
    // take 22 registers for the whole loop.
    const PairTask* task = tasks + FindTask(tasks, num_tasks, item);
    const uint32_t first = (item - task->item_begin) * kQueriesPerItem;
    const uint32_t last = min(first + kQueriesPerItem, task->a.num_features);
    int32_t* results = best + task->best_offset;
    // One call site for both directions keeps one copy of MatchQuery.
    uint32_t i = first;
    int forward = -1;
    bool reverse = false;
    while (i < last) {
      const int answer = query(task, reverse, reverse ? static_cast<uint32_t>(forward) : i, params, scratch);
      if (kCrossCheck && !reverse && answer >= 0) {
        forward = answer;
        reverse = true;
        continue;
      }
      const int result = !reverse ? answer : (answer == static_cast<int>(i) ? forward : -1);
      if (lane == 0) results[i] = result;
      reverse = false;
      ++i;
    }
  }
}

constexpr int kCompactThreads = 256;

// One block per task: order-preserving compaction of the kept matches.
__global__ void __launch_bounds__(kCompactThreads) CompactKernel(const PairTask* tasks, const int32_t* best,
                                                                 uint2* out, MatchSegment* segments,
                                                                 uint32_t* cursor) {
  __shared__ uint32_t warp_counts[kCompactThreads / 32];
  __shared__ uint32_t s_begin;
  const PairTask& task = tasks[blockIdx.x];
  const uint32_t n = task.a.num_features;
  const int32_t* results = best + task.best_offset;
  const unsigned lane = LaneId(), warp = threadIdx.x >> 5;

  uint32_t total = 0;
  for (uint32_t base = 0; base < n; base += kCompactThreads) {
    const uint32_t i = base + threadIdx.x;
    total += __syncthreads_count(i < n && results[i] >= 0);
  }
  if (threadIdx.x == 0) {
    s_begin = atomicAdd(cursor, total);
    segments[blockIdx.x] = MatchSegment{s_begin, total};
  }
  __syncthreads();
  uint32_t written = s_begin;
  for (uint32_t base = 0; base < n; base += kCompactThreads) {
    const uint32_t i = base + threadIdx.x;
    const int j = i < n ? results[i] : -1;
    const unsigned keep = __ballot_sync(kFullWarpMask, j >= 0);
    if (lane == 0) warp_counts[warp] = __popc(keep);
    __syncthreads();
    uint32_t before = 0, chunk = 0;
    for (unsigned w = 0; w < kCompactThreads / 32; ++w) {
      before += w < warp ? warp_counts[w] : 0;
      chunk += warp_counts[w];
    }
    if (j >= 0) out[written + before + __popc(keep & ((1u << lane) - 1))] = make_uint2(i, uint32_t(j));
    written += chunk;
    __syncthreads();
  }
}

}  // namespace

int CascadeMatchGridSize(int device) {
  int sms = 0, per_sm = 0;
  CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
  CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&per_sm, CascadeMatchKernel<true, DirectQuery>,
                                                           kThreads, 0));
  return sms * (per_sm > 0 ? per_sm : 1);
}

namespace {

template <class Query>
void LaunchMatchKernel(const PairTask* tasks, int num_tasks, uint32_t total_items, const MatchParams& params,
                       const Query& query, bool cross_check, int grid_size, int32_t* best, cudaStream_t stream) {
  if (num_tasks == 0 || total_items == 0) return;
  const uint32_t needed = (total_items + kThreads / 32 - 1) / (kThreads / 32);
  const int grid = static_cast<int>(needed < static_cast<uint32_t>(grid_size) ? needed : static_cast<uint32_t>(grid_size));
  if (cross_check) {
    CascadeMatchKernel<true, Query><<<grid, kThreads, 0, stream>>>(tasks, num_tasks, total_items, params, query, best);
  } else {
    CascadeMatchKernel<false, Query><<<grid, kThreads, 0, stream>>>(tasks, num_tasks, total_items, params, query, best);
  }
  CUDA_CHECK_LAUNCH();
}

}  // namespace

void LaunchCascadeMatch(const PairTask* tasks, int num_tasks, uint32_t total_items, const MatchParams& params,
                        bool cross_check, int grid_size, int32_t* best, cudaStream_t stream) {
  LaunchMatchKernel(tasks, num_tasks, total_items, params, DirectQuery{}, cross_check, grid_size, best, stream);
}

void LaunchCascadeSelect(const PairTask* tasks, int num_tasks, uint32_t total_items, const MatchParams& params,
                         const CandidateLists& lists, bool cross_check, int grid_size, int32_t* best,
                         cudaStream_t stream) {
  LaunchMatchKernel(tasks, num_tasks, total_items, params, ListQuery{lists}, cross_check, grid_size, best, stream);
}

void LaunchCascadeMatchGuided(const PairTask* tasks, int num_tasks, uint32_t total_items, const MatchParams& params,
                              const EpipolarGuideDevice* guides, const float2* points, double max_distance,
                              bool cross_check, int grid_size, int32_t* best, cudaStream_t stream) {
  const GuidedDirectQuery query{Guidance{tasks, guides, points, max_distance}};
  LaunchMatchKernel(tasks, num_tasks, total_items, params, query, cross_check, grid_size, best, stream);
}

void LaunchCascadeSelectGuided(const PairTask* tasks, int num_tasks, uint32_t total_items, const MatchParams& params,
                               const CandidateLists& lists, const EpipolarGuideDevice* guides, const float2* points,
                               double max_distance, bool cross_check, int grid_size, int32_t* best,
                               cudaStream_t stream) {
  const GuidedListQuery query{lists, Guidance{tasks, guides, points, max_distance}};
  LaunchMatchKernel(tasks, num_tasks, total_items, params, query, cross_check, grid_size, best, stream);
}

void LaunchCompactMatches(const PairTask* tasks, int num_tasks, const int32_t* best, uint2* out,
                          MatchSegment* segments, uint32_t* cursor, cudaStream_t stream) {
  if (num_tasks == 0) return;
  CompactKernel<<<num_tasks, kCompactThreads, 0, stream>>>(tasks, best, out, segments, cursor);
  CUDA_CHECK_LAUNCH();
}

}  // namespace cuda
}  // namespace cashash
