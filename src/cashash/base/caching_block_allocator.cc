#include "cashash/base/caching_block_allocator.h"

#include <algorithm>
#include <iterator>
#include <string>

#include "cashash/base/device_memory_error.h"

namespace cashash {
namespace {

std::string MiB(size_t bytes) { return std::to_string((bytes + (size_t{1} << 20) - 1) >> 20) + " MiB"; }

}  // namespace

CachingBlockAllocator::CachingBlockAllocator(BlockSource* source, size_t budget_bytes, const char* memory_name)
    : source_(source), budget_(budget_bytes), memory_name_(memory_name) {}

CachingBlockAllocator::~CachingBlockAllocator() {
  for (const auto& [bytes, block] : cached_) source_->Free(block);
  for (const auto& [block, bytes] : lent_) source_->Free(block);
}

size_t CachingBlockAllocator::SizeClass(size_t bytes) {
  const size_t rounded = (std::max<size_t>(bytes, 1) + kGranularity - 1) / kGranularity * kGranularity;
  if (rounded <= kFirstClassBytes) return rounded;
  // 2^k < rounded <= 2^(k+1): classes 2^k + j * 2^k / kClassesPerDoubling.
  size_t power = kFirstClassBytes;
  while (power * 2 < rounded) power *= 2;
  const size_t step = power / kClassesPerDoubling;
  const size_t size = (rounded + step - 1) / step * step;
  return size <= kPageFromBytes ? size : (size + kPageBytes - 1) / kPageBytes * kPageBytes;
}

void* CachingBlockAllocator::Acquire(size_t bytes, const char* what) {
  if (bytes == 0) return nullptr;
  const size_t size = SizeClass(bytes);
  std::lock_guard<std::mutex> lock(mutex_);
  const auto hit = cached_.find(size);
  if (hit != cached_.end()) {
    void* block = hit->second;
    cached_.erase(hit);
    stats_.cached_bytes -= size;
    stats_.in_use_bytes += size;
    ++stats_.reuses;
    lent_.emplace(block, size);
    NoteHeld();
    return block;
  }
  if (!MakeRoom(size)) {
    throw DeviceMemoryError(std::string(memory_name_) + " budget exceeded by " + what + ": it needs " + MiB(size) +
                            ", " + MiB(stats_.in_use_bytes) + " of " + MiB(budget_) + " are in use");
  }
  void* block = source_->Allocate(size);
  if (block == nullptr && !cached_.empty()) {
    // The device is fuller than the budget says (another process, or no
    // budget): everything cached goes back before the last try.
    while (!cached_.empty()) FreeCached(cached_.begin());
    block = source_->Allocate(size);
  }
  if (block == nullptr) {
    throw DeviceMemoryError("out of " + std::string(memory_name_) + " allocating " + MiB(size) + " for " + what + " (" +
                            MiB(stats_.in_use_bytes) + " in use by this run)");
  }
  ++stats_.source_allocations;
  stats_.in_use_bytes += size;
  lent_.emplace(block, size);
  NoteHeld();
  return block;
}

void CachingBlockAllocator::Release(void* block) {
  if (block == nullptr) return;
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = lent_.find(block);
  if (it == lent_.end()) return;  // not ours: nothing to give back
  const size_t size = it->second;
  lent_.erase(it);
  stats_.in_use_bytes -= size;
  stats_.cached_bytes += size;
  cached_.emplace(size, block);
}

void CachingBlockAllocator::Trim() {
  std::lock_guard<std::mutex> lock(mutex_);
  while (!cached_.empty()) FreeCached(cached_.begin());
}

BlockAllocatorStats CachingBlockAllocator::Stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

bool CachingBlockAllocator::MakeRoom(size_t needed) {
  if (budget_ == 0) return true;
  auto fits = [&] { return stats_.held_bytes() <= budget_ && needed <= budget_ - stats_.held_bytes(); };
  while (!fits() && !cached_.empty()) FreeCached(std::prev(cached_.end()));
  return fits();
}

void CachingBlockAllocator::FreeCached(std::multimap<size_t, void*>::iterator it) {
  source_->Free(it->second);
  stats_.cached_bytes -= it->first;
  ++stats_.trimmed_blocks;
  cached_.erase(it);
}

void CachingBlockAllocator::NoteHeld() {
  stats_.peak_held_bytes = std::max(stats_.peak_held_bytes, stats_.held_bytes());
  stats_.peak_in_use_bytes = std::max(stats_.peak_in_use_bytes, stats_.in_use_bytes);
}

}  // namespace cashash
