// Hashing of descriptors and construction of the per-image bucket tables on
// the device: one launch sequence for a whole batch of newly added images.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "cashash_cuda/matching/device_image.cuh"

namespace cashash {
namespace cuda {

// Features hashed by one thread block.
constexpr int kHashFeaturesPerBlock = 32;
// Bucket bits (num_tables * bits_per_table) must fit one 64-bit signature.
constexpr int kMaxSignatureBits = 64;

// One image to hash: its parts and the first block of the launch that works
// on it (blocks of kHashFeaturesPerBlock features, images back to back).
struct HashJob {
  DeviceImageParts parts;
  uint32_t block_begin = 0;
};

struct HashParams {
  // Projection rows transposed to 128 x rows_padded (column r = row r of the
  // CascadeProjections matrix), padded with zero rows to a multiple of 32.
  const float* projections_t = nullptr;
  // Per row: dot(row, rounded mean), so that bit = dot(row, desc) > offset.
  // Rows and descriptors are small integers, so every partial sum is an
  // integer below 2^24 and the float arithmetic is exact in any order.
  const float* row_offsets = nullptr;  // rows_padded floats
  int num_tables = 0;
  int bits_per_table = 0;
  int rows_padded = 0;
};

// Hashes every feature of every job, fills signatures and remap codes, and
// builds the bucket CSR of each table by counting sort. The offsets region of
// each image must be zeroed before. Asynchronous on `stream`.
void LaunchHashAndBucket(const HashJob* jobs, int num_jobs, uint32_t total_blocks, const HashParams& params,
                         cudaStream_t stream);

}  // namespace cuda
}  // namespace cashash
