#include "cashash/base/caching_block_allocator.h"

#include <algorithm>
#include <iterator>
#include <string>

#include "cashash/base/device_memory_error.h"

namespace cashash {
namespace {

std::string MiB(size_t bytes) { return std::to_string((bytes + (size_t{1} << 20) - 1) >> 20) + " MiB"; }

size_t RoundUp(size_t bytes, size_t unit) { return (bytes + unit - 1) / unit * unit; }

// A slab of several blocks aims at this many of them (one page at least,
// kSlabBytes at most).
constexpr size_t kBlocksPerSlabTarget = 16;

}  // namespace

CachingBlockAllocator::CachingBlockAllocator(BlockSource* source, size_t budget_bytes, const char* memory_name,
                                             bool slabs)
    : source_(source), budget_(budget_bytes), memory_name_(memory_name), slabs_(slabs && budget_bytes == 0) {}

CachingBlockAllocator::~CachingBlockAllocator() {
  for (const auto& [base, slab] : slab_map_) source_->Free(base);
}

size_t CachingBlockAllocator::SlabBlockClass(size_t bytes) {
  const size_t rounded = RoundUp(std::max<size_t>(bytes, 1), kGranularity);
  if (rounded <= kFirstClassBytes) return rounded;
  // 2^k < rounded <= 2^(k+1): classes 2^k + j * 2^k / kClassesPerDoubling.
  size_t power = kFirstClassBytes;
  while (power * 2 < rounded) power *= 2;
  return RoundUp(rounded, power / kClassesPerDoubling);
}

size_t CachingBlockAllocator::SizeClass(size_t bytes) {
  const size_t size = SlabBlockClass(bytes);
  return size <= kPageFromBytes ? size : RoundUp(size, kPageBytes);
}

size_t CachingBlockAllocator::BlocksPerSlab(size_t size) {
  if (size >= kSlabBytes) return 1;
  const size_t target = std::min(kSlabBytes, std::max(kPageBytes, size * kBlocksPerSlabTarget));
  // As many as the target holds, then as many as its whole pages hold.
  const size_t pages = RoundUp(target / size * size, kPageBytes);
  return std::max<size_t>(1, std::min(pages, kSlabBytes) / size);
}

void* CachingBlockAllocator::Acquire(size_t bytes, const char* what) {
  if (bytes == 0) return nullptr;
  const size_t size = slabs_ ? SlabBlockClass(bytes) : SizeClass(bytes);
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<void*>& free = free_[size];
  if (!free.empty()) {
    void* block = free.back();
    free.pop_back();
    --SlabOf(block)->second.free_blocks;
    lent_.emplace(block, size);
    stats_.in_use_bytes += size;
    stats_.cached_bytes -= size;
    ++stats_.reuses;
    NoteHeld();
    return block;
  }
  // Several blocks to a slab without a budget, else one (a slab of one
  // block takes whole pages above kPageFromBytes: SizeClass already is).
  const size_t blocks = slabs_ ? BlocksPerSlab(size) : 1;
  const size_t slab_bytes = size <= kPageFromBytes && blocks == 1 ? size : RoundUp(blocks * size, kPageBytes);
  if (!MakeRoom(slab_bytes)) {
    throw DeviceMemoryError(std::string(memory_name_) + " budget exceeded by " + what + ": it needs " + MiB(size) +
                            ", " + MiB(stats_.in_use_bytes) + " of " + MiB(budget_) + " are in use");
  }
  void* block = TakeNewSlab(size, blocks, slab_bytes);
  if (block == nullptr && blocks > 1) {
    block = TakeNewSlab(size, 1, size <= kPageFromBytes ? size : RoundUp(size, kPageBytes));
  }
  if (block == nullptr) {
    throw DeviceMemoryError("out of " + std::string(memory_name_) + " allocating " + MiB(size) + " for " + what +
                            " (" + MiB(stats_.in_use_bytes) + " in use by this run)");
  }
  return block;
}

void* CachingBlockAllocator::TakeNewSlab(size_t size, size_t blocks, size_t bytes) {
  void* base = source_->Allocate(bytes);
  if (base == nullptr) {
    // The device is fuller than the books say (another process, or no
    // budget): every free slab goes back before the last try.
    FreeAllFreeSlabs();
    base = source_->Allocate(bytes);
  }
  if (base == nullptr) return nullptr;
  char* first = static_cast<char*>(base);
  Slab& slab = slab_map_[first];
  slab.bytes = bytes;
  slab.block_bytes = size;
  slab.blocks = blocks;
  slab.free_blocks = blocks - 1;
  std::vector<void*>& free = free_[size];
  for (size_t k = blocks; k-- > 1;) free.push_back(first + k * size);  // the next block taken is the second
  held_ += bytes;
  stats_.cached_bytes = held_ - stats_.in_use_bytes - size;
  stats_.in_use_bytes += size;
  ++stats_.source_allocations;
  lent_.emplace(base, size);
  NoteHeld();
  return base;
}

void CachingBlockAllocator::Release(void* block) {
  if (block == nullptr) return;
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = lent_.find(block);
  if (it == lent_.end()) return;  // not ours: nothing to give back
  const size_t size = it->second;
  lent_.erase(it);
  free_[size].push_back(block);
  ++SlabOf(block)->second.free_blocks;
  stats_.in_use_bytes -= size;
  stats_.cached_bytes += size;
}

void CachingBlockAllocator::Trim() {
  std::lock_guard<std::mutex> lock(mutex_);
  FreeAllFreeSlabs();
}

BlockAllocatorStats CachingBlockAllocator::Stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

bool CachingBlockAllocator::MakeRoom(size_t needed) {
  if (budget_ == 0) return true;
  auto fits = [&] { return held_ <= budget_ && needed <= budget_ - held_; };
  while (!fits()) {
    SlabMap::iterator largest = slab_map_.end();
    for (auto it = slab_map_.begin(); it != slab_map_.end(); ++it) {
      if (it->second.free_blocks == it->second.blocks &&
          (largest == slab_map_.end() || it->second.bytes > largest->second.bytes)) {
        largest = it;
      }
    }
    if (largest == slab_map_.end()) return false;
    FreeSlab(largest);
  }
  return true;
}

void CachingBlockAllocator::FreeAllFreeSlabs() {
  for (auto it = slab_map_.begin(); it != slab_map_.end();) {
    const auto next = std::next(it);
    if (it->second.free_blocks == it->second.blocks) FreeSlab(it);
    it = next;
  }
}

void CachingBlockAllocator::FreeSlab(SlabMap::iterator it) {
  char* const base = it->first;
  const Slab slab = it->second;
  std::vector<void*>& free = free_[slab.block_bytes];
  free.erase(std::remove_if(free.begin(), free.end(),
                            [&](void* block) {
                              char* b = static_cast<char*>(block);
                              return b >= base && b < base + slab.bytes;
                            }),
             free.end());
  source_->Free(base);
  held_ -= slab.bytes;
  stats_.cached_bytes -= slab.bytes;
  ++stats_.trimmed_blocks;
  slab_map_.erase(it);
}

CachingBlockAllocator::SlabMap::iterator CachingBlockAllocator::SlabOf(void* block) {
  // The slab with the largest base not above the block.
  auto it = slab_map_.upper_bound(static_cast<char*>(block));
  return std::prev(it);
}

void CachingBlockAllocator::NoteHeld() {
  stats_.peak_held_bytes = std::max(stats_.peak_held_bytes, stats_.held_bytes());
  stats_.peak_in_use_bytes = std::max(stats_.peak_in_use_bytes, stats_.in_use_bytes);
}

}  // namespace cashash
