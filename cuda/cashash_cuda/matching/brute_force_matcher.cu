// Kernels of the exact GPU brute-force matcher (see brute_force_matcher.cuh
// and docs/gpu_brute_force_design.md for the design and its floor).
//
// BestTwoKernel: one thread block takes 256 query rows of one problem; each of
// its 4 warps keeps the u8 fragments of its 64 rows in registers for the whole
// run and sweeps every row of b, 128 at a time, through a double-buffered
// shared-memory tile. Per 8 columns a warp issues 16 m16n8k32 u8 mma (K = 128
// exactly: the dot products are exact in s32) and folds the 64x8 dots into its
// rows' running best two with packed (score, position) keys, three min/max per
// dot, unless no dot of the 64x8 beats its row's second best so far: then
// nothing can change and the fold is skipped. MatchPairs runs it twice per
// pair: forward over every row, then in reverse over the rows HitGatherKernel
// gathered.
//
// HitGatherKernel: with cross-check, one block per pair copies the rows of
// image 2 that an accepted forward match names; the reverse search then runs
// over those rows only (MatchPairs).
//
// MutualMatchKernel: one block per pair applies COLMAP's acceptance rule via a
// table of the host's own acos values (so the GPU decides exactly as the CPU)
// and the cross-check, and compacts the matches in idx1 order.
#include "cashash_cuda/matching/brute_force_matcher.cuh"

#include <algorithm>
#include <cstring>
#include <stdexcept>
#include <string>

#include "cashash/matching/descriptor_distance.h"
#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/tensor_core_u8.cuh"
#include "cashash_cuda/utils/warp_best_two.cuh"

namespace cashash {
namespace cuda {
namespace {

constexpr int kThreads = 128;
constexpr int kWarpRows = 64;                        // 4 m16 tiles per warp
constexpr int kBlockRows = kWarpRows * kThreads / 32;  // 256
constexpr int kTileCols = 128;                       // b rows per shared tile
constexpr int kRowBytes = 128;
constexpr int kSmemStride = 144;  // 128 + 16: conflict-free ldmatrix rows
constexpr int kTileBytes = kTileCols * kSmemStride;
static_assert(kTileCols <= PackedBestTwo::kPositions, "tile positions must fit the packed key");

// Dots at or above 512^2 all have angle 0 (the cosine is clamped to 1).
constexpr int kAngleTableMaxDot = 512 * 512;

// 2 blocks per SM with the strip loop unrolled twice was the fastest of the
// variants measured on an H100 at 8,192 features (pairs/s, blocks per SM /
// unroll): 2/2 19,584; 3/2 19,244; 3/1 19,492; 2/1 19,556; 4/1 18,599
// (128 registers, spills). Occupancy is not the limit.
constexpr int kMinBlocksPerSm = 2;  // blocks per SM the register budget is sized for
constexpr int kStripUnroll = 2;     // 8-column strips per unrolled step

// -(s + 1) for each of a lane's 8 row slots, s the row's second best so far
// over the four lanes that share it (each holds the best two of its own
// columns): BestTwoKernel's accumulators start there.
__device__ __forceinline__ void RowSecondBias(const IndexedBestTwo (&best)[8], int (&bias)[8]) {
#pragma unroll
  for (int slot = 0; slot < 8; ++slot) {
    int row_best = best[slot].best, row_second = best[slot].second;
#pragma unroll
    for (int offset = 1; offset < 4; offset <<= 1) {
      const int other_best = __shfl_xor_sync(0xffffffffu, row_best, offset);
      const int other_second = __shfl_xor_sync(0xffffffffu, row_second, offset);
      row_second = max(min(row_best, other_best), max(row_second, other_second));
      row_best = max(row_best, other_best);
    }
    bias[slot] = -(row_second + 1);
  }
}

// Folds one 8-column strip's products (dot - s - 1, accumulator j of m tile
// i: slot 2i + (j >= 2), column 2t + (j & 1)) into the windows, unless none
// in the warp is >= 0: then no row's best two can change.
__device__ __forceinline__ void FoldStrip(const int (&acc)[4][4], int key_scale, int position_key,
                                          PackedBestTwo (&window)[8]) {
  // All 16 negative iff their AND is negative.
  int all = acc[0][0];
#pragma unroll
  for (int i = 0; i < 4; ++i) all &= acc[i][0] & acc[i][1] & acc[i][2] & acc[i][3];
  if (!__any_sync(0xffffffffu, all >= 0)) return;
#pragma unroll
  for (int i = 0; i < 4; ++i) {
    window[2 * i].Push(acc[i][0] * key_scale + position_key);
    window[2 * i].Push(acc[i][1] * key_scale + position_key - 1);
    window[2 * i + 1].Push(acc[i][2] * key_scale + position_key);
    window[2 * i + 1].Push(acc[i][3] * key_scale + position_key - 1);
  }
}

// A fragments of the warp's 64 rows from warp_row0, all of K: [m tile][k
// step][register]. Register r holds row g (+8 for r odd) and bytes
// 4t..4t+3 (+16 for r >= 2) of the k step, the m16n8k32 row-major layout.
// Rows from n_a on are zero.
__device__ __forceinline__ void LoadFragmentsA(const BestTwoProblem& p, int n_a, int warp_row0, int g, int t,
                                               uint32_t (&a)[4][4][4]) {
#pragma unroll
  for (int i = 0; i < 4; ++i) {
    const int row_lo = warp_row0 + 16 * i + g;
    const int row_hi = row_lo + 8;
    const uint32_t* lo = reinterpret_cast<const uint32_t*>(p.a + static_cast<size_t>(row_lo) * kRowBytes);
    const uint32_t* hi = reinterpret_cast<const uint32_t*>(p.a + static_cast<size_t>(row_hi) * kRowBytes);
    const bool lo_ok = row_lo < n_a;
    const bool hi_ok = row_hi < n_a;
#pragma unroll
    for (int s = 0; s < 4; ++s) {
      a[i][s][0] = lo_ok ? __ldg(lo + 8 * s + t) : 0u;
      a[i][s][1] = hi_ok ? __ldg(hi + 8 * s + t) : 0u;
      a[i][s][2] = lo_ok ? __ldg(lo + 8 * s + 4 + t) : 0u;
      a[i][s][3] = hi_ok ? __ldg(hi + 8 * s + 4 + t) : 0u;
    }
  }
}

// Starts the asynchronous copy of b's rows tile * kTileCols .. + kTileCols - 1
// into shared stage `stage`. Rows of b past n_b are zero-filled: their dot 0
// never beats a real column (which has a lower index) and equals the default
// second best.
__device__ __forceinline__ void LoadTileB(uint8_t (&tiles)[2][kTileBytes], const BestTwoProblem& p, int tile,
                                          int stage) {
  const int col0 = tile * kTileCols;
  const uint32_t base = SharedAddress(&tiles[stage][0]);
#pragma unroll
  for (int q = 0; q < kTileCols * kRowBytes / 16 / kThreads; ++q) {
    const int chunk = threadIdx.x + q * kThreads;
    const int row = chunk >> 3;
    const int part = chunk & 7;
    const bool valid = col0 + row < p.n_b;
    const uint8_t* src = valid ? p.b + static_cast<size_t>(col0 + row) * kRowBytes + part * 16 : p.b;
    CopyAsync16(base + row * kSmemStride + part * 16, src, valid);
  }
}

// The products of one shared tile, 8 columns per strip, folded into the
// windows. `stage` is this lane's ldmatrix address in the tile.
__device__ __forceinline__ void SweepTile(uint32_t stage, const uint32_t (&a)[4][4][4], const int (&bias)[8],
                                          int key_scale, int t, PackedBestTwo (&window)[8]) {
#pragma unroll(kStripUnroll)
  for (int n = 0; n < kTileCols / 8; ++n) {
    uint32_t b[8];
    {
      uint32_t r[4];
      LoadMatrixX4(stage + n * 8 * kSmemStride, r);
      b[0] = r[0]; b[1] = r[1]; b[2] = r[2]; b[3] = r[3];
      LoadMatrixX4(stage + n * 8 * kSmemStride + 64, r);
      b[4] = r[0]; b[5] = r[1]; b[6] = r[2]; b[7] = r[3];
    }
    int acc[4][4];
#pragma unroll
    for (int i = 0; i < 4; ++i) {
      acc[i][0] = acc[i][1] = bias[2 * i];
      acc[i][2] = acc[i][3] = bias[2 * i + 1];
    }
#pragma unroll
    for (int s = 0; s < 4; ++s) {
#pragma unroll
      for (int i = 0; i < 4; ++i) MmaU8(acc[i], a[i][s], b[2 * s], b[2 * s + 1]);
    }
    // Accumulator j of tile i: row 16i + g (+8 for j >= 2), column
    // n*8 + 2t + (j & 1), holding dot - second - 1. key = that * 256 +
    // (255 - column in tile); the scale comes in as a kernel argument so
    // the multiply stays an IMAD (FMA pipe) instead of a shift on the
    // min/max (ALU) pipe.
    const int position_key = PackedBestTwo::kPositions - 1 - (n * 8 + 2 * t);
    FoldStrip(acc, key_scale, position_key, window);
  }
}

// Adds one tile's windows (keys relative to the tile's seconds) to the
// running best two of each row slot, and empties them.
__device__ __forceinline__ void MergeWindows(const int (&bias)[8], int col0, PackedBestTwo (&window)[8],
                                             IndexedBestTwo (&best)[8]) {
#pragma unroll
  for (int slot = 0; slot < 8; ++slot) {
    if (!window[slot].Empty()) {  // pushes come two at a time, so the second is set too
      best[slot].Merge(window[slot].BestScore() - bias[slot], col0 + window[slot].BestPosition(),
                       window[slot].SecondScore() - bias[slot]);
    }
    window[slot].Reset();
  }
}

// Each row's best two over the four lanes that share it, written by the
// group's first lane.
__device__ __forceinline__ void WriteBestTwo(const BestTwoProblem& p, int n_a, int warp_row0, int g, int t,
                                             IndexedBestTwo (&best)[8]) {
#pragma unroll
  for (int slot = 0; slot < 8; ++slot) {
    best[slot].WarpGroupMerge<4>();
    const int row = warp_row0 + 16 * (slot >> 1) + g + 8 * (slot & 1);
    if (t == 0 && row < n_a) {
      const bool found = best[slot].best > 0;
      p.best_dot[row] = found ? best[slot].best : 0;
      p.best_idx[row] = found ? best[slot].index : -1;
      p.second_dot[row] = best[slot].second;
    }
  }
}

// The warp's A fragments (a[4][4][4]) and best-two slots stay in registers
// across the whole double-buffered sweep over b: the helpers are inlined
// and their fully unrolled mma and fold loops index those arrays with
// constants only.
__global__ void __launch_bounds__(kThreads, kMinBlocksPerSm)
    BestTwoKernel(const BestTwoProblem* __restrict__ problems, const int2* __restrict__ items, int key_scale) {
  __shared__ __align__(128) uint8_t tiles[2][kTileBytes];

  const int2 item = items[blockIdx.x];
  const BestTwoProblem p = problems[item.x];
  // A reverse search is launched for its capacity; the rows past the count
  // the gather wrote leave at once (the whole block, before any barrier).
  const int n_a = p.live_rows != nullptr ? min(p.n_a, *p.live_rows) : p.n_a;
  if (item.y * kBlockRows >= n_a) return;
  const int lane = threadIdx.x & 31;
  const int warp = threadIdx.x >> 5;
  const int g = lane >> 2;  // mma group: fragment row
  const int t = lane & 3;   // thread in group: fragment column pair
  const int warp_row0 = item.y * kBlockRows + warp * kWarpRows;

  uint32_t a[4][4][4];
  LoadFragmentsA(p, n_a, warp_row0, g, t, a);

  // Slot 2i + h: row 16i + g + 8h of the warp.
  PackedBestTwo window[8];
  IndexedBestTwo best[8];

  const int num_tiles = (p.n_b + kTileCols - 1) / kTileCols;
  if (num_tiles > 0) LoadTileB(tiles, p, 0, 0);
  CopyAsyncCommit();
  // ldmatrix x4: lanes 8m..8m+7 address rows 0..7 of matrix m, which is the
  // 16-byte column block m of the 8 b rows (k steps 2 per x4).
  const uint32_t lane_offset = (lane & 7) * kSmemStride + (lane >> 3) * 16;

  for (int tile = 0; tile < num_tiles; ++tile) {
    if (tile + 1 < num_tiles) LoadTileB(tiles, p, tile + 1, (tile + 1) & 1);
    CopyAsyncCommit();
    CopyAsyncWait<1>();
    __syncthreads();
    // A dot at most its row's second best so far changes nothing: the two
    // dots that make that second stay, the second only grows, and a tie
    // with the best goes to the best's lower, earlier column. So the
    // accumulators start at -(second + 1), the products come out as
    // dot - second - 1, >= 0 exactly where a dot can matter, and an 8-column
    // strip where none can in the whole warp skips the fold (three min/max
    // and a multiply-add per dot). The second is the row's, over the four
    // lanes that share it (each holds the best two of its own columns): with
    // random order a row's second is beaten by about 2 of the next j columns
    // after j, so most strips past the first thousand columns skip. The
    // window then holds keys relative to the tile's seconds, which the merge
    // adds back.
    int bias[8];
    RowSecondBias(best, bias);
    SweepTile(SharedAddress(&tiles[tile & 1][0]) + lane_offset, a, bias, key_scale, t, window);
    MergeWindows(bias, tile * kTileCols, window, best);
    __syncthreads();  // the stage is refilled by the next iteration's load
  }
  WriteBestTwo(p, n_a, warp_row0, g, t, best);
}

__device__ __forceinline__ bool AcceptOnDevice(int dot, int second, int index, const float* __restrict__ angle,
                                               float max_ratio, float max_distance) {
  if (index < 0) return false;
  const float best_angle = __ldg(angle + min(dot, kAngleTableMaxDot));
  if (best_angle > max_distance) return false;
  const float second_angle = __ldg(angle + min(second, kAngleTableMaxDot));
  return best_angle < __fmul_rn(max_ratio, second_angle);
}

constexpr int kMatchThreads = 256;

// Position of each thread's flag among the set flags of the block, in thread
// order, and their total; warp_counts holds kMatchThreads / 32 ints. Ends
// with a barrier, so warp_counts may be reused at once.
__device__ __forceinline__ int BlockCompactSlot(bool flag, int* warp_counts, int* total) {
  const int lane = threadIdx.x & 31;
  const int warp = threadIdx.x >> 5;
  const unsigned ballot = __ballot_sync(0xffffffffu, flag);
  if (lane == 0) warp_counts[warp] = __popc(ballot);
  __syncthreads();
  int offset = 0;
  int sum = 0;
#pragma unroll
  for (int w = 0; w < kMatchThreads / 32; ++w) {
    offset += w < warp ? warp_counts[w] : 0;
    sum += warp_counts[w];
  }
  __syncthreads();
  *total = sum;
  return offset + __popc(ballot & ((1u << lane) - 1u));
}

__global__ void __launch_bounds__(kMatchThreads)
    HitGatherKernel(const HitGatherProblem* __restrict__ problems, const float* __restrict__ angle,
                    MatchThresholds thresholds) {
  __shared__ int warp_counts[kMatchThreads / 32];
  const HitGatherProblem p = problems[blockIdx.x];
  // slot[] first holds a flag per row of image 2: named by an accepted
  // forward match or not. The block's barriers order these global writes.
  for (int j = threadIdx.x; j < p.n2; j += kMatchThreads) p.slot[j] = 0;
  __syncthreads();
  for (int i = threadIdx.x; i < p.n1; i += kMatchThreads) {
    const int j = p.best_idx12[i];
    if (j >= 0 && j < p.n2 &&
        AcceptOnDevice(p.best_dot12[i], p.second_dot12[i], j, angle, thresholds.max_ratio, thresholds.max_distance)) {
      p.slot[j] = 1;
    }
  }
  __syncthreads();
  // Flags to positions, in ascending row order, and the rows copied there.
  int written = 0;
  for (int base = 0; base < p.n2; base += kMatchThreads) {
    const int j = base + threadIdx.x;
    const bool needed = j < p.n2 && p.slot[j] != 0;
    int total = 0;
    const int position = written + BlockCompactSlot(needed, warp_counts, &total);
    if (j < p.n2) p.slot[j] = needed ? position : -1;
    if (needed) {
      const uint4* src = reinterpret_cast<const uint4*>(p.b + static_cast<size_t>(j) * kRowBytes);
      uint4* dst = reinterpret_cast<uint4*>(p.gathered + static_cast<size_t>(position) * kRowBytes);
#pragma unroll
      for (int q = 0; q < kRowBytes / 16; ++q) dst[q] = __ldg(src + q);
    }
    written += total;
  }
  if (threadIdx.x == 0) *p.num_gathered = written;
}

__global__ void __launch_bounds__(kMatchThreads)
    MutualMatchKernel(const MutualMatchProblem* __restrict__ problems, const float* __restrict__ angle,
                      MatchThresholds thresholds) {
  __shared__ int warp_counts[kMatchThreads / 32];
  const MutualMatchProblem p = problems[blockIdx.x];
  int written = 0;
  for (int base = 0; base < p.n1; base += kMatchThreads) {
    const int i = base + threadIdx.x;
    int j = -1;
    bool keep = false;
    if (i < p.n1) {
      j = p.best_idx12[i];
      keep = AcceptOnDevice(p.best_dot12[i], p.second_dot12[i], j, angle, thresholds.max_ratio,
                            thresholds.max_distance);
      if (keep && thresholds.cross_check) {
        const int r = j >= p.n2 ? -1 : p.slot21 != nullptr ? p.slot21[j] : j;
        keep = r >= 0 && p.best_idx21[r] == i &&
               AcceptOnDevice(p.best_dot21[r], p.second_dot21[r], i, angle, thresholds.max_ratio,
                              thresholds.max_distance);
      }
    }
    int total = 0;
    const int slot = written + BlockCompactSlot(keep, warp_counts, &total);
    if (keep) {
      p.matches[2 * slot] = static_cast<uint32_t>(i);
      p.matches[2 * slot + 1] = static_cast<uint32_t>(j);
    }
    written += total;
  }
  if (threadIdx.x == 0) *p.num_matches = written;
}

// Device or pinned host memory of a GpuResources that only grows; growing
// waits for the stream first, since queued work may still read the old
// block (only this stream uses it, so the block can then go back at once).
class GrowingBuffer {
 public:
  GrowingBuffer(bool pinned_host) : pinned_host_(pinned_host) {}
  ~GrowingBuffer() { Free(); }
  GrowingBuffer(const GrowingBuffer&) = delete;
  GrowingBuffer& operator=(const GrowingBuffer&) = delete;

  void* Reserve(GpuResources* owner, size_t bytes, cudaStream_t stream) {
    if (bytes <= bytes_) return ptr_;
    CUDA_CHECK(cudaStreamSynchronize(stream));
    Free();
    const size_t grown = std::max(bytes, bytes_ * 3 / 2);
    ptr_ = pinned_host_ ? owner->AllocatePinned(grown, "brute-force results")
                        : owner->AllocateDevice(grown, "brute-force scratch");
    owner_ = owner;
    bytes_ = grown;
    return ptr_;
  }

 private:
  void Free() {
    if (ptr_ != nullptr) {
      if (pinned_host_) owner_->FreePinned(ptr_);
      else owner_->FreeDevice(ptr_);
    }
    ptr_ = nullptr;
    bytes_ = 0;
  }
  bool pinned_host_;
  GpuResources* owner_ = nullptr;
  void* ptr_ = nullptr;
  size_t bytes_ = 0;
};

}  // namespace

struct BruteForceKernels::Scratch {
  GrowingBuffer angle_table{false};
  GrowingBuffer problems{false};  // BestTwoProblem[] then int2 items[]
  GrowingBuffer reverse_problems{false};  // the reverse searches' BestTwoProblem[] and items
  GrowingBuffer gather{false};    // HitGatherProblem[]
  GrowingBuffer mutual{false};    // MutualMatchProblem[]
  GrowingBuffer results{false};   // MatchPairs: best-two outputs, matches, counts
  GrowingBuffer host_counts{true};
  GrowingBuffer host_matches{true};
  const float* angle = nullptr;
};

BruteForceKernels::BruteForceKernels(cudaStream_t stream, GpuResources* resources)
    : stream_(stream), resources_(resources), scratch_(new Scratch) {
  try {
    // The host's own angle of every dot that can differ from angle 0, so the
    // device's decisions are bit-identical to AcceptSiftMatch on the CPU.
    std::vector<float> table(kAngleTableMaxDot + 1);
    for (int dot = 0; dot <= kAngleTableMaxDot; ++dot) table[dot] = DescriptorDotToAngle(dot);
    void* device_table = scratch_->angle_table.Reserve(resources_, table.size() * sizeof(float), stream_);
    CUDA_CHECK(cudaMemcpyAsync(device_table, table.data(), table.size() * sizeof(float), cudaMemcpyHostToDevice,
                               stream_));
    CUDA_CHECK(cudaStreamSynchronize(stream_));
    scratch_->angle = static_cast<const float*>(device_table);
  } catch (...) {
    delete scratch_;
    throw;
  }
}

BruteForceKernels::~BruteForceKernels() {
  if (scratch_ != nullptr) cudaStreamSynchronize(stream_);
  delete scratch_;
}

namespace {

// Stages the problems and their items in `staging` and launches one
// BestTwoKernel over them.
void LaunchBestTwo(const std::vector<BestTwoProblem>& problems, GpuResources* owner, GrowingBuffer* staging,
                   cudaStream_t stream) {
  std::vector<int2> items;
  for (size_t k = 0; k < problems.size(); ++k) {
    const BestTwoProblem& p = problems[k];
    if (p.n_a < 0 || p.n_b < 0 || (p.n_a > 0 && p.a == nullptr) || (p.n_b > 0 && p.b == nullptr)) {
      throw std::invalid_argument("BestTwo: bad problem " + std::to_string(k));
    }
    if ((reinterpret_cast<uintptr_t>(p.a) | reinterpret_cast<uintptr_t>(p.b)) % 16 != 0) {
      throw std::invalid_argument("BestTwo: descriptors must be 16-byte aligned, problem " + std::to_string(k));
    }
    for (int block = 0; block * kBlockRows < p.n_a; ++block) items.push_back(make_int2(static_cast<int>(k), block));
  }
  if (items.empty()) return;
  const size_t problem_bytes = (problems.size() * sizeof(BestTwoProblem) + 15) / 16 * 16;
  const size_t item_bytes = items.size() * sizeof(int2);
  std::vector<uint8_t> staged(problem_bytes + item_bytes);
  std::memcpy(staged.data(), problems.data(), problems.size() * sizeof(BestTwoProblem));
  std::memcpy(staged.data() + problem_bytes, items.data(), item_bytes);
  uint8_t* device = static_cast<uint8_t*>(staging->Reserve(owner, staged.size(), stream));
  CUDA_CHECK(cudaMemcpyAsync(device, staged.data(), staged.size(), cudaMemcpyHostToDevice, stream));
  BestTwoKernel<<<static_cast<unsigned>(items.size()), kThreads, 0, stream>>>(
      reinterpret_cast<const BestTwoProblem*>(device), reinterpret_cast<const int2*>(device + problem_bytes),
      PackedBestTwo::kPositions);
  CUDA_CHECK_LAUNCH();
}

}  // namespace

void BruteForceKernels::EnqueueBestTwo(const std::vector<BestTwoProblem>& problems) {
  LaunchBestTwo(problems, resources_, &scratch_->problems, stream_);
}

void BruteForceKernels::EnqueueHitGather(const std::vector<HitGatherProblem>& problems,
                                         const MatchThresholds& thresholds) {
  if (problems.empty()) return;
  for (size_t k = 0; k < problems.size(); ++k) {
    if (reinterpret_cast<uintptr_t>(problems[k].gathered) % 16 != 0) {
      throw std::invalid_argument("EnqueueHitGather: gathered rows must be 16-byte aligned, problem " +
                                  std::to_string(k));
    }
  }
  const size_t bytes = problems.size() * sizeof(HitGatherProblem);
  void* device = scratch_->gather.Reserve(resources_, bytes, stream_);
  CUDA_CHECK(cudaMemcpyAsync(device, problems.data(), bytes, cudaMemcpyHostToDevice, stream_));
  HitGatherKernel<<<static_cast<unsigned>(problems.size()), kMatchThreads, 0, stream_>>>(
      static_cast<const HitGatherProblem*>(device), scratch_->angle, thresholds);
  CUDA_CHECK_LAUNCH();
}

void BruteForceKernels::EnqueueMutualMatches(const std::vector<MutualMatchProblem>& problems,
                                             const MatchThresholds& thresholds) {
  if (problems.empty()) return;
  const size_t bytes = problems.size() * sizeof(MutualMatchProblem);
  void* device = scratch_->mutual.Reserve(resources_, bytes, stream_);
  CUDA_CHECK(cudaMemcpyAsync(device, problems.data(), bytes, cudaMemcpyHostToDevice, stream_));
  MutualMatchKernel<<<static_cast<unsigned>(problems.size()), kMatchThreads, 0, stream_>>>(
      static_cast<const MutualMatchProblem*>(device), scratch_->angle, thresholds);
  CUDA_CHECK_LAUNCH();
}

size_t BruteForceKernels::MatchPairsScratchBytes(int n1, int n2) {
  // 3 ints per row each way, 2 uint32 per possible match, one count; the
  // gather's slot per image-2 row, its count, and room for every image-2 row
  // gathered (128 bytes each, after up to 3 ints of alignment).
  const size_t ints = 3 * static_cast<size_t>(n1) + 3 * static_cast<size_t>(n2) + 2 * static_cast<size_t>(n1) + 1 +
                      static_cast<size_t>(n2) + 1 + 3 + static_cast<size_t>(n2) * kRowBytes / 4;
  return ints * 4;
}

namespace {

// The problems of MatchPairs' four launches.
struct PairProblems {
  std::vector<BestTwoProblem> forward;
  std::vector<HitGatherProblem> gather;
  std::vector<BestTwoProblem> reverse;
  std::vector<MutualMatchProblem> mutual;
};

// Carves each pair's outputs and scratch from `cursor` onwards (room for
// MatchPairsScratchBytes per pair) and links the problems through them:
// forward search, gather of the named rows, reverse search over those,
// acceptance. Pair k's match count goes to counts[k].
PairProblems LayOutPairProblems(const std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>>& pairs,
                                bool cross_check, int* counts, int* cursor) {
  auto take = [&cursor](size_t n) {
    int* p = cursor;
    cursor += n;
    return p;
  };
  auto take_rows = [&cursor](int rows) {  // 16-byte aligned descriptor rows
    while (reinterpret_cast<uintptr_t>(cursor) % 16 != 0) ++cursor;
    uint8_t* p = reinterpret_cast<uint8_t*>(cursor);
    cursor += static_cast<size_t>(rows) * kRowBytes / 4;
    return p;
  };
  PairProblems out;
  for (size_t k = 0; k < pairs.size(); ++k) {
    const DeviceDescriptors& d1 = pairs[k].first;
    const DeviceDescriptors& d2 = pairs[k].second;
    BestTwoProblem p12{d1.data, d2.data, take(d1.rows), take(d1.rows), take(d1.rows), d1.rows, d2.rows};
    out.forward.push_back(p12);
    MutualMatchProblem m;
    m.best_dot12 = p12.best_dot;
    m.second_dot12 = p12.second_dot;
    m.best_idx12 = p12.best_idx;
    m.matches = reinterpret_cast<uint32_t*>(take(2 * static_cast<size_t>(d1.rows)));
    m.num_matches = counts + k;
    m.n1 = d1.rows;
    m.n2 = d2.rows;
    if (cross_check) {
      HitGatherProblem g{p12.best_dot, p12.second_dot, p12.best_idx, d2.data, take(d2.rows), nullptr, take(1),
                         d1.rows, d2.rows};
      g.gathered = take_rows(d2.rows);
      out.gather.push_back(g);
      // Sized for every row of image 2; the gather's count decides.
      BestTwoProblem p21{g.gathered, d1.data, take(d2.rows), take(d2.rows), take(d2.rows),
                         d2.rows,    d1.rows, g.num_gathered};
      out.reverse.push_back(p21);
      m.best_dot21 = p21.best_dot;
      m.second_dot21 = p21.second_dot;
      m.best_idx21 = p21.best_idx;
      m.slot21 = g.slot;
    }
    out.mutual.push_back(m);
  }
  return out;
}

}  // namespace

std::vector<FeatureMatches> BruteForceKernels::MatchPairs(
    const std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>>& pairs, const MatchThresholds& thresholds) {
  if (pairs.empty()) return {};
  size_t total = pairs.size();
  for (const auto& pair : pairs) total += MatchPairsScratchBytes(pair.first.rows, pair.second.rows) / 4;
  int* counts = static_cast<int*>(scratch_->results.Reserve(resources_, total * 4, stream_));  // one per pair, first
  const PairProblems problems = LayOutPairProblems(pairs, thresholds.cross_check, counts, counts + pairs.size());
  EnqueueBestTwo(problems.forward);
  EnqueueHitGather(problems.gather, thresholds);
  LaunchBestTwo(problems.reverse, resources_, &scratch_->reverse_problems, stream_);
  EnqueueMutualMatches(problems.mutual, thresholds);
  return CopyMatchesBack(problems.mutual, counts);
}

std::vector<FeatureMatches> BruteForceKernels::CopyMatchesBack(const std::vector<MutualMatchProblem>& mutual,
                                                               const int* device_counts) {
  const size_t n = mutual.size();
  int* host_counts = static_cast<int*>(scratch_->host_counts.Reserve(resources_, n * sizeof(int), stream_));
  CUDA_CHECK(cudaMemcpyAsync(host_counts, device_counts, n * sizeof(int), cudaMemcpyDeviceToHost, stream_));
  CUDA_CHECK(cudaStreamSynchronize(stream_));
  const std::vector<int> counts(host_counts, host_counts + n);  // the buffer below may be regrown
  size_t num_matches = 0;
  for (const int count : counts) num_matches += static_cast<size_t>(count);
  FeatureMatch* host_matches = static_cast<FeatureMatch*>(
      scratch_->host_matches.Reserve(resources_, std::max<size_t>(num_matches, 1) * sizeof(FeatureMatch), stream_));
  size_t offset = 0;
  for (size_t k = 0; k < n; ++k) {
    if (counts[k] == 0) continue;
    CUDA_CHECK(cudaMemcpyAsync(host_matches + offset, mutual[k].matches, counts[k] * sizeof(FeatureMatch),
                               cudaMemcpyDeviceToHost, stream_));
    offset += counts[k];
  }
  CUDA_CHECK(cudaStreamSynchronize(stream_));
  std::vector<FeatureMatches> result(n);
  offset = 0;
  for (size_t k = 0; k < n; ++k) {
    result[k].assign(host_matches + offset, host_matches + offset + counts[k]);
    offset += counts[k];
  }
  return result;
}

std::vector<FeatureMatches> MatchPairsInBatches(BruteForceKernels* kernels,
                                                const std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>>& pairs,
                                                const MatchThresholds& thresholds, size_t batch_scratch_bytes) {
  std::vector<FeatureMatches> results(pairs.size());
  std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>> batch;
  std::vector<size_t> batch_pairs;
  size_t scratch = 0;
  const auto flush = [&]() {
    if (batch.empty()) return;
    std::vector<FeatureMatches> matches = kernels->MatchPairs(batch, thresholds);
    for (size_t k = 0; k < batch.size(); ++k) results[batch_pairs[k]] = std::move(matches[k]);
    batch.clear();
    batch_pairs.clear();
    scratch = 0;
  };
  for (size_t i = 0; i < pairs.size(); ++i) {
    const DeviceDescriptors& a = pairs[i].first;
    const DeviceDescriptors& b = pairs[i].second;
    if (a.rows == 0 || b.rows == 0) continue;
    const size_t bytes = BruteForceKernels::MatchPairsScratchBytes(a.rows, b.rows);
    if (!batch.empty() && scratch + bytes > batch_scratch_bytes) flush();
    batch.push_back(pairs[i]);
    batch_pairs.push_back(i);
    scratch += bytes;
  }
  flush();
  return results;
}

}  // namespace cuda
}  // namespace cashash
