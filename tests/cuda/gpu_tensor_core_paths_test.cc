// The 7.5 path of the u8 tensor-core and warp-reduction primitives (plain
// loads, m8n8k16 mma, xor-shuffles) against the CPU, on any device of 7.5 or
// newer, beside the path this build picked for the device: exact integers
// on both, so exact matching is exact on every card.
#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

#include "gpu_test_support.h"
#include "cashash_cuda/utils/tensor_core_paths.cuh"

namespace cashash {
namespace cuda {
namespace {

std::vector<uint8_t> RandomRows(int rows, std::mt19937& rng) {
  std::uniform_int_distribution<int> byte(0, 255);
  std::vector<uint8_t> data(static_cast<size_t>(rows) * 128);
  for (uint8_t& v : data) v = static_cast<uint8_t>(byte(rng));
  return data;
}

std::vector<int32_t> CpuDots(const std::vector<uint8_t>& a, int rows_a, const std::vector<uint8_t>& b, int rows_b) {
  std::vector<int32_t> out(static_cast<size_t>(rows_a) * rows_b);
  for (int i = 0; i < rows_a; ++i) {
    for (int j = 0; j < rows_b; ++j) {
      int32_t sum = 0;
      for (int k = 0; k < 128; ++k) sum += int32_t{a[i * 128 + k]} * int32_t{b[j * 128 + k]};
      out[static_cast<size_t>(i) * rows_b + j] = sum;
    }
  }
  return out;
}

TEST(GpuTensorCorePaths, U8DotProductsEqualTheCpuOnBothPaths) {
  SKIP_WITHOUT_CUDA_DEVICE();
  std::mt19937 rng(44);
  const int rows_a = 64, rows_b = 40;
  std::vector<uint8_t> a = RandomRows(rows_a, rng), b = RandomRows(rows_b, rng);
  // The largest products (all 255) and rows of one hot byte, which catch a
  // byte or fragment landing in the wrong place.
  for (int k = 0; k < 128; ++k) a[k] = b[k] = 255;
  for (int k = 0; k < 128; ++k) a[128 + k] = k == 77 ? 1 : 0;
  const std::vector<int32_t> expected = CpuDots(a, rows_a, b, rows_b);
  EXPECT_EQ(expected[0], 128 * 255 * 255);
  EXPECT_EQ(U8DotProductsOnDevice(a, rows_a, b, rows_b, TensorCorePath::kSm75), expected);
  EXPECT_EQ(U8DotProductsOnDevice(a, rows_a, b, rows_b, TensorCorePath::kBuilt), expected);
}

TEST(GpuTensorCorePaths, WarpReductionsEqualTheCpuOnBothPaths) {
  SKIP_WITHOUT_CUDA_DEVICE();
  std::mt19937 rng(7544);
  const int warps = 16;
  std::vector<uint32_t> values(32 * warps);
  for (int w = 0; w < warps; ++w) {
    for (int l = 0; l < 32; ++l) {
      // Sparse bits in some warps (the OR of one-hot lanes), full range in others.
      values[32 * w + l] = w % 2 == 0 ? (rng() % 3 == 0 ? 1u << (rng() % 32) : 0u) : static_cast<uint32_t>(rng());
    }
  }
  std::vector<uint32_t> expected(4 * warps);
  for (int w = 0; w < warps; ++w) {
    uint32_t r_or = 0, r_min = 0xffffffffu, r_max = 0, r_add = 0;
    for (int l = 0; l < 32; ++l) {
      const uint32_t v = values[32 * w + l];
      r_or |= v;
      r_min = std::min(r_min, v);
      r_max = std::max(r_max, v);
      r_add += v;
    }
    expected[4 * w] = r_or;
    expected[4 * w + 1] = r_min;
    expected[4 * w + 2] = r_max;
    expected[4 * w + 3] = r_add;
  }
  EXPECT_EQ(WarpReductionsOnDevice(values, TensorCorePath::kSm75), expected);
  EXPECT_EQ(WarpReductionsOnDevice(values, TensorCorePath::kBuilt), expected);
}

}  // namespace
}  // namespace cuda
}  // namespace cashash
