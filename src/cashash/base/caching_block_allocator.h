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
// freed block serve any request of its class.
//
// Blocks live in slabs, one source allocation each. Without a budget a slab
// holds several blocks of one class (up to kSlabBytes, a whole number of
// 2 MiB pages: what cudaMalloc takes for a block above 1 MiB anyway), so a
// run of hundreds of images makes a few dozen cudaMalloc calls. Under a
// budget every block is a slab of its own, rounded up to whole pages above
// 1 MiB (SizeClass): any cached block can then be given back alone, and the
// books count what the device gives.
//
// One budget: what is held (all slabs, blocks in use and cached alike)
// never passes `budget_bytes`. A request that would pass it first gives
// cached blocks back to the source, largest first; only when the blocks in
// use alone leave no room does it throw DeviceMemoryError. A source that
// fails (the device itself is full) gets every free slab back and one more
// try (without a budget, then with a slab of one block).
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
  size_t cached_bytes = 0;         // held but not lent: free blocks kept for reuse
  size_t peak_held_bytes = 0;      // most of in use + cached at any time
  size_t peak_in_use_bytes = 0;
  size_t source_allocations = 0;   // slabs taken from the source
  size_t reuses = 0;               // requests served from the cache
  size_t trimmed_blocks = 0;       // slabs given back (to make room, or by Trim)
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
  // Blocks above kPageFromBytes take whole kPageBytes pages of the source.
  static constexpr size_t kPageFromBytes = size_t{1} << 20;
  static constexpr size_t kPageBytes = size_t{2} << 20;
  // Most bytes of a slab of several blocks (without a budget).
  static constexpr size_t kSlabBytes = size_t{32} << 20;

  // `budget_bytes` 0: no budget but what the source can give. `memory_name`
  // names the memory in errors ("GPU memory"). `slabs`: without a budget,
  // several blocks of a class per source allocation (a source whose blocks
  // must each be an allocation of their own, as pinned host memory whose
  // device address is asked for, passes false).
  CachingBlockAllocator(BlockSource* source, size_t budget_bytes, const char* memory_name = "GPU memory",
                        bool slabs = true);
  // Gives every slab back; blocks still lent out are the caller's error.
  ~CachingBlockAllocator();
  CachingBlockAllocator(const CachingBlockAllocator&) = delete;
  CachingBlockAllocator& operator=(const CachingBlockAllocator&) = delete;

  // The class of a request of `bytes` (> 0) under a budget: four per
  // doubling, above kPageFromBytes whole pages.
  static size_t SizeClass(size_t bytes);
  // The class without the page rounding (blocks in slabs).
  static size_t SlabBlockClass(size_t bytes);
  // Blocks of class `size` (SlabBlockClass) in one slab: as many as fit
  // kSlabBytes in a whole number of pages; 1 where none does.
  static size_t BlocksPerSlab(size_t size);

  // A block of at least `bytes` (null for 0). Throws DeviceMemoryError
  // naming `what` when the budget or the source has no room.
  void* Acquire(size_t bytes, const char* what);
  // `block` from Acquire; no one may use it any more.
  void Release(void* block);
  // Gives every slab whose blocks are all free back to the source.
  void Trim();

  size_t budget_bytes() const { return budget_; }
  BlockAllocatorStats Stats() const;

 private:
  struct Slab {
    size_t bytes = 0;        // taken from the source
    size_t block_bytes = 0;  // its blocks' class
    size_t blocks = 0;
    size_t free_blocks = 0;
  };
  using SlabMap = std::map<char*, Slab>;

  // Makes a slab of `blocks` blocks of class `size` (`bytes` in all) and
  // lends its first block; null when the budget or the source has no room.
  void* TakeNewSlab(size_t size, size_t blocks, size_t bytes);
  // Frees slabs whose blocks are all free, largest first, until `needed`
  // more bytes fit the budget or none is left; true if they fit.
  bool MakeRoom(size_t needed);
  void FreeAllFreeSlabs();
  void FreeSlab(SlabMap::iterator it);
  SlabMap::iterator SlabOf(void* block);
  void NoteHeld();

  BlockSource* const source_;
  const size_t budget_;
  const char* const memory_name_;
  const bool slabs_;
  mutable std::mutex mutex_;
  SlabMap slab_map_;                                    // by base address
  std::unordered_map<size_t, std::vector<void*>> free_;  // class -> free blocks, last freed last
  std::unordered_map<void*, size_t> lent_;              // block -> class
  size_t held_ = 0;                                      // bytes of all slabs
  BlockAllocatorStats stats_;
};

}  // namespace cashash
