#include "cashash_cuda/utils/tensor_core_paths.cuh"

#include <stdexcept>

#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/device_memory.cuh"
#include "cashash_cuda/utils/tensor_core_u8.cuh"
#include "cashash_cuda/utils/warp_primitives.cuh"

namespace cashash {
namespace cuda {
namespace {

constexpr int kRowBytes = 128;
constexpr int kStride = 144;  // as the brute-force kernel's tiles

// One warp per 16 x 8 block of products: b's 8 rows through shared memory
// and ldmatrix, a's fragments from global memory, four k steps of 32 bytes.
template <bool kSm75>
__global__ void U8ProductsKernel(const uint8_t* __restrict__ a, const uint8_t* __restrict__ b, int rows_b,
                                 int32_t* __restrict__ out) {
  __shared__ __align__(128) uint8_t tile[8 * kStride];
  const int lane = static_cast<int>(threadIdx.x);
  const int g = lane >> 2, t = lane & 3;
  const int row0 = static_cast<int>(blockIdx.x) * 16, col0 = static_cast<int>(blockIdx.y) * 8;
  const uint32_t base = SharedAddress(tile);
#pragma unroll
  for (int q = 0; q < 2; ++q) {
    const int chunk = lane + 32 * q, row = chunk >> 3, part = chunk & 7;
    const uint8_t* src = b + static_cast<size_t>(col0 + row) * kRowBytes + part * 16;
    if (kSm75) {
      CopyPlain16(base + row * kStride + part * 16, src, true);
    } else {
      CopyAsync16(base + row * kStride + part * 16, src, true);
    }
  }
  CopyAsyncCommit();
  CopyAsyncWait<0>();
  __syncthreads();
  const uint32_t lane_offset = (lane & 7) * kStride + (lane >> 3) * 16;
  uint32_t bf[8], r[4];
  LoadMatrixX4(base + lane_offset, r);
  bf[0] = r[0]; bf[1] = r[1]; bf[2] = r[2]; bf[3] = r[3];
  LoadMatrixX4(base + lane_offset + 64, r);
  bf[4] = r[0]; bf[5] = r[1]; bf[6] = r[2]; bf[7] = r[3];
  const uint32_t* lo = reinterpret_cast<const uint32_t*>(a + static_cast<size_t>(row0 + g) * kRowBytes);
  const uint32_t* hi = reinterpret_cast<const uint32_t*>(a + static_cast<size_t>(row0 + g + 8) * kRowBytes);
  int acc[4] = {0, 0, 0, 0};
#pragma unroll
  for (int s = 0; s < 4; ++s) {
    const uint32_t af[4] = {lo[8 * s + t], hi[8 * s + t], lo[8 * s + 4 + t], hi[8 * s + 4 + t]};
    if (kSm75) {
      MmaU8Sm75(acc, af, bf[2 * s], bf[2 * s + 1]);
    } else {
      MmaU8(acc, af, bf[2 * s], bf[2 * s + 1]);
    }
  }
  int32_t* lo_out = out + static_cast<size_t>(row0 + g) * rows_b + col0 + 2 * t;
  int32_t* hi_out = out + static_cast<size_t>(row0 + g + 8) * rows_b + col0 + 2 * t;
  lo_out[0] = acc[0];
  lo_out[1] = acc[1];
  hi_out[0] = acc[2];
  hi_out[1] = acc[3];
}

template <bool kSm75>
__global__ void WarpReductionsKernel(const uint32_t* __restrict__ values, uint32_t* __restrict__ out) {
  const uint32_t v = values[blockIdx.x * 32 + threadIdx.x];
  const uint32_t r_or = kSm75 ? WarpReduceOrShuffle(v) : WarpReduceOr(v);
  const uint32_t r_min = kSm75 ? WarpReduceMinShuffle(v) : WarpReduceMin(v);
  const uint32_t r_max = kSm75 ? WarpReduceMaxShuffle(v) : WarpReduceMax(v);
  const uint32_t r_add = kSm75 ? WarpReduceAddShuffle(v) : WarpReduceAdd(v);
  if (threadIdx.x == 0) {
    out[4 * blockIdx.x + 0] = r_or;
    out[4 * blockIdx.x + 1] = r_min;
    out[4 * blockIdx.x + 2] = r_max;
    out[4 * blockIdx.x + 3] = r_add;
  }
}

int CurrentDevice() {
  int device = 0;
  CUDA_CHECK(cudaGetDevice(&device));
  return device;
}

}  // namespace

std::vector<int32_t> U8DotProductsOnDevice(const std::vector<uint8_t>& a, int rows_a, const std::vector<uint8_t>& b,
                                           int rows_b, TensorCorePath path) {
  if (rows_a <= 0 || rows_b <= 0 || rows_a % 16 != 0 || rows_b % 8 != 0 ||
      a.size() != static_cast<size_t>(rows_a) * kRowBytes || b.size() != static_cast<size_t>(rows_b) * kRowBytes) {
    throw std::invalid_argument("U8DotProductsOnDevice: rows_a must be a multiple of 16, rows_b of 8, rows of 128 bytes");
  }
  const size_t products = static_cast<size_t>(rows_a) * rows_b;
  GpuResources resources(CurrentDevice(), 0);
  DeviceBuffer d_a(&resources, a.size(), "test rows a"), d_b(&resources, b.size(), "test rows b");
  DeviceBuffer d_out(&resources, products * sizeof(int32_t), "test products");
  CUDA_CHECK(cudaMemcpy(d_a.as<uint8_t>(), a.data(), a.size(), cudaMemcpyHostToDevice));
  CUDA_CHECK(cudaMemcpy(d_b.as<uint8_t>(), b.data(), b.size(), cudaMemcpyHostToDevice));
  CUDA_CHECK(cudaMemset(d_out.as<int32_t>(), 0xff, products * sizeof(int32_t)));  // poison: every product is written
  const dim3 grid(static_cast<unsigned>(rows_a / 16), static_cast<unsigned>(rows_b / 8));
  if (path == TensorCorePath::kSm75) {
    U8ProductsKernel<true><<<grid, 32>>>(d_a.as<uint8_t>(), d_b.as<uint8_t>(), rows_b, d_out.as<int32_t>());
  } else {
    U8ProductsKernel<false><<<grid, 32>>>(d_a.as<uint8_t>(), d_b.as<uint8_t>(), rows_b, d_out.as<int32_t>());
  }
  CUDA_CHECK_LAUNCH();
  std::vector<int32_t> out(products);
  CUDA_CHECK(cudaMemcpy(out.data(), d_out.as<int32_t>(), products * sizeof(int32_t), cudaMemcpyDeviceToHost));
  return out;
}

std::vector<uint32_t> WarpReductionsOnDevice(const std::vector<uint32_t>& values, TensorCorePath path) {
  if (values.empty() || values.size() % 32 != 0) {
    throw std::invalid_argument("WarpReductionsOnDevice: a multiple of 32 values");
  }
  const unsigned warps = static_cast<unsigned>(values.size() / 32);
  GpuResources resources(CurrentDevice(), 0);
  DeviceBuffer d_values(&resources, values.size() * sizeof(uint32_t), "test values");
  DeviceBuffer d_out(&resources, warps * 4 * sizeof(uint32_t), "test reductions");
  CUDA_CHECK(cudaMemcpy(d_values.as<uint32_t>(), values.data(), values.size() * sizeof(uint32_t),
                        cudaMemcpyHostToDevice));
  if (path == TensorCorePath::kSm75) {
    WarpReductionsKernel<true><<<warps, 32>>>(d_values.as<uint32_t>(), d_out.as<uint32_t>());
  } else {
    WarpReductionsKernel<false><<<warps, 32>>>(d_values.as<uint32_t>(), d_out.as<uint32_t>());
  }
  CUDA_CHECK_LAUNCH();
  std::vector<uint32_t> out(warps * 4);
  CUDA_CHECK(cudaMemcpy(out.data(), d_out.as<uint32_t>(), out.size() * sizeof(uint32_t), cudaMemcpyDeviceToHost));
  return out;
}

}  // namespace cuda
}  // namespace cashash
