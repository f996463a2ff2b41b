// The bookkeeping of a caching allocator under one budget, without the
// memory itself: blocks come from a BlockSource (cudaMalloc on a device, or
// anything in a test), are rounded up to a size class, and go back to a
// cache of free blocks of their class when released, so that a later
// request of the same class costs no allocation (a cudaMalloc is about a
// third of a millisecond, a cudaFree waits for the whole device).
//
// Size classes, not exact sizes: images of varying feature counts ask for
// sizes that rarely repeat exactly, so a cache keyed by exact size keeps
// growing towards the whole database. Four classes per doubling (sizes
// 2^k x {1.25, 1.5, 1.75, 2}) waste at most a fifth of a block and let a
// freed block serve any request of its class. Classes above 1 MiB are also
// whole 2 MiB pages, which is what cudaMalloc takes for such a block
// anyway: the books then count what the device gives.
//
// One budget: what is held (blocks in use plus cached free ones) never
// passes `budget_bytes`. A request that would pass it first gives cached
// blocks back to the source, largest first; only when the blocks in use
// alone leave no room does it throw DeviceMemoryError. A source that fails
// (the device itself is full) gets the whole cache back and one more try.
//
// Thread-safe: a block may be released on another thread than the one that
// acquired it (the exact rematch's tickets).
#pragma once

#include <cstddef>
#include <map>
#include <mutex>
#include <unordered_map>
#include <vector>

namespace cashash {

// Where a CachingBlockAllocator's blocks come from and go back to.
class BlockSource {
 public:
  virtual ~BlockSource() = default;
  // A block of `bytes`, or null when there is no room for it (any other
  // failure throws).
  virtual void* Allocate(size_t bytes) = 0;
  virtual void Free(void* block) = 0;
};

struct BlockAllocatorStats {
  size_t in_use_bytes = 0;         // blocks lent out (size-class bytes)
  size_t cached_bytes = 0;         // free blocks kept for reuse
  size_t peak_held_bytes = 0;      // most of in use + cached at any time
  size_t peak_in_use_bytes = 0;
  size_t source_allocations = 0;   // blocks taken from the source
  size_t reuses = 0;               // requests served from the cache
  size_t trimmed_blocks = 0;       // cached blocks given back to make room
  size_t held_bytes() const { return in_use_bytes + cached_bytes; }
};

class CachingBlockAllocator {
 public:
  // Requests are rounded up to at least this (and to its multiples below
  // kFirstClassBytes), which is also the blocks' alignment in a source that
  // returns aligned memory.
  static constexpr size_t kGranularity = 256;
  // Below this every multiple of kGranularity is its own class.
  static constexpr size_t kFirstClassBytes = size_t{64} << 10;
  static constexpr int kClassesPerDoubling = 4;
  // Classes above kPageFromBytes are multiples of kPageBytes.
  static constexpr size_t kPageFromBytes = size_t{1} << 20;
  static constexpr size_t kPageBytes = size_t{2} << 20;

  // `budget_bytes` 0: no budget but what the source can give. `memory_name`
  // names the memory in errors ("GPU memory").
  CachingBlockAllocator(BlockSource* source, size_t budget_bytes, const char* memory_name = "GPU memory");
  // Gives every cached block back; blocks still lent out are the caller's
  // error and are given back too.
  ~CachingBlockAllocator();
  CachingBlockAllocator(const CachingBlockAllocator&) = delete;
  CachingBlockAllocator& operator=(const CachingBlockAllocator&) = delete;

  // The size class of a request of `bytes` (> 0).
  static size_t SizeClass(size_t bytes);

  // A block of at least `bytes` (null for 0). Throws DeviceMemoryError
  // naming `what` when the budget or the source has no room.
  void* Acquire(size_t bytes, const char* what);
  // `block` from Acquire; no one may use it any more.
  void Release(void* block);
  // Gives every cached block back to the source.
  void Trim();

  size_t budget_bytes() const { return budget_; }
  BlockAllocatorStats Stats() const;

 private:
  // Frees cached blocks, largest first, until `needed` more bytes fit the
  // budget or nothing is cached; true if they fit. Holds mutex_.
  bool MakeRoom(size_t needed);
  void FreeCached(std::multimap<size_t, void*>::iterator it);
  void NoteHeld();

  BlockSource* const source_;
  const size_t budget_;
  const char* const memory_name_;
  mutable std::mutex mutex_;
  std::multimap<size_t, void*> cached_;        // class bytes -> free block
  std::unordered_map<void*, size_t> lent_;    // block -> class bytes
  BlockAllocatorStats stats_;
};

}  // namespace cashash
