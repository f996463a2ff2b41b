// The primitives of tensor_core_u8.cuh and warp_primitives.cuh along either
// of their compile-time paths, run on the current device (tests): the path
// this binary picked for the device (kBuilt: cp.async, m16n8k32 and redux
// from 8.0 on) or the 7.5 path (plain loads, four m8n8k16, xor-shuffles),
// which every architecture from 7.5 on can run. Both must give exactly the
// CPU's integers. Host declarations only, so C++ tests include this file.
#pragma once

#include <cstdint>
#include <vector>

namespace cashash {
namespace cuda {

enum class TensorCorePath { kBuilt, kSm75 };

// All dot products of the 128-byte rows of a (rows_a, a multiple of 16) with
// those of b (rows_b, a multiple of 8): rows_a x rows_b, row-major, through
// shared-memory tiles, ldmatrix and the u8 mma of `path`.
std::vector<int32_t> U8DotProductsOnDevice(const std::vector<uint8_t>& a, int rows_a, const std::vector<uint8_t>& b,
                                           int rows_b, TensorCorePath path);

// Per warp of 32 values: OR, min, max and sum over the warp (4 results per
// warp), through the warp reductions of `path`.
std::vector<uint32_t> WarpReductionsOnDevice(const std::vector<uint32_t>& values, TensorCorePath path);

}  // namespace cuda
}  // namespace cashash
