// Where one image's cascade data lives on the device. Everything is carved
// out of one block per image (see DeviceImageLayout), taken from the
// device's GpuResources, so that adding and removing an image costs one
// request to its cache of blocks.
#pragma once

#include <cstddef>
#include <cstdint>

namespace cashash {
namespace cuda {

// One feature as seen from a bucket: its remap code, its bucket signature
// (for de-duplication across tables) and its row. Stored once per table in
// bucket order, so that scanning a bucket is one contiguous, coalesced read.
struct alignas(16) BucketEntry {
  uint64_t code_lo;  // remap bits 0..63
  uint64_t code_hi;  // remap bits 64..127
  uint64_t signature;  // bucket id of table t in bits t*b .. t*b+b-1
  uint32_t index;    // feature row
  uint32_t table_shift;  // t * bits_per_table for the table t that lists it (duplicate test)
};
static_assert(sizeof(BucketEntry) == 32, "two 16-byte loads per entry");

// Read-only view passed to the kernels (by value).
struct DeviceImageView {
  const uint8_t* descriptors = nullptr;  // n x 128
  const uint64_t* signatures = nullptr;  // n
  const ulonglong2* codes = nullptr;     // n, (bits 0..63, bits 64..127)
  const uint32_t* offsets = nullptr;     // tables x (buckets + 1), CSR starts
  const BucketEntry* entries = nullptr;  // tables x n, bucket-sorted per table
  uint32_t num_features = 0;
};

// Writable pointers used while hashing and building the buckets.
struct DeviceImageParts {
  uint8_t* descriptors = nullptr;
  uint64_t* signatures = nullptr;
  ulonglong2* codes = nullptr;
  uint32_t* offsets = nullptr;
  uint32_t* cursors = nullptr;  // tables x buckets, scatter positions
  BucketEntry* entries = nullptr;
  uint32_t num_features = 0;

  DeviceImageView View() const {
    DeviceImageView v;
    v.descriptors = descriptors;
    v.signatures = signatures;
    v.codes = codes;
    v.offsets = offsets;
    v.entries = entries;
    v.num_features = num_features;
    return v;
  }
};

// Byte offsets of the parts inside one allocation (every part 256-aligned).
struct DeviceImageLayout {
  size_t descriptors = 0, signatures = 0, codes = 0, offsets = 0, cursors = 0, entries = 0;
  size_t offsets_bytes = 0;
  size_t total = 0;

  DeviceImageLayout(size_t num_features, int num_tables, int bits_per_table) {
    const size_t buckets = size_t{1} << bits_per_table;
    size_t at = 0;
    auto take = [&at](size_t bytes) {
      const size_t start = at;
      at += (bytes + 255) & ~size_t{255};
      return start;
    };
    descriptors = take(num_features * 128);
    signatures = take(num_features * sizeof(uint64_t));
    codes = take(num_features * 16);
    offsets_bytes = num_tables * (buckets + 1) * sizeof(uint32_t);
    offsets = take(offsets_bytes);
    cursors = take(num_tables * buckets * sizeof(uint32_t));
    entries = take(num_tables * num_features * sizeof(BucketEntry));
    total = at;
  }

  DeviceImageParts Parts(void* base, uint32_t num_features) const {
    char* b = static_cast<char*>(base);
    DeviceImageParts p;
    p.descriptors = reinterpret_cast<uint8_t*>(b + descriptors);
    p.signatures = reinterpret_cast<uint64_t*>(b + signatures);
    p.codes = reinterpret_cast<ulonglong2*>(b + codes);
    p.offsets = reinterpret_cast<uint32_t*>(b + offsets);
    p.cursors = reinterpret_cast<uint32_t*>(b + cursors);
    p.entries = reinterpret_cast<BucketEntry*>(b + entries);
    p.num_features = num_features;
    return p;
  }
};

}  // namespace cuda
}  // namespace cashash
