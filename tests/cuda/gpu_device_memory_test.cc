// The owner of a device's memory (GpuResources) that holds the GPU
// matchers' images, the pinned ring that uploads them, and both backends'
// images through them: blocks are reused by size class, the budget trims
// the cache before it refuses, staged uploads arrive intact, and images
// added again after removal (their blocks recycled) match as before.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "cashash/base/caching_block_allocator.h"
#include "cashash/base/device_memory_error.h"
#include "synthetic_sift.h"
#include "cashash/matchers/exact_matcher.h"
#include "gpu_test_support.h"
#include "cashash_cuda/utils/device_memory.cuh"
#include "cashash_cuda/utils/gpu_resources.h"
#include "cascade_options.h"

namespace cashash {
namespace {

using testing_support::CascadeOptions;

TEST(GpuResources, BlocksAreDistinctAlignedAndReusedByClass) {
  SKIP_WITHOUT_CUDA_DEVICE();
  cuda::GpuResources resources(0, 0);
  char* a = static_cast<char*>(resources.AllocateDevice(100000, "test"));
  char* b = static_cast<char*>(resources.AllocateDevice(100000, "test"));
  EXPECT_NE(a, b);
  EXPECT_GE(static_cast<size_t>(std::max(a, b) - std::min(a, b)), 100000u);  // no overlap
  EXPECT_EQ(reinterpret_cast<uintptr_t>(b) % CachingBlockAllocator::kGranularity, 0u);
  resources.FreeDevice(a);
  // Another size of the same class (98,304 < bytes <= 114,688): the freed block.
  EXPECT_EQ(resources.AllocateDevice(99000, "test"), a);
  const BlockAllocatorStats stats = resources.DeviceStats();
  EXPECT_EQ(stats.source_allocations, 1u) << "without a budget both blocks come from one slab";
  // b was a free block of a's slab and the last request took a back: both
  // served without a new allocation.
  EXPECT_EQ(stats.reuses, 2u);
  // Blocks are device memory: a round trip through one of them.
  std::vector<int> host(250, 7), back(250, 0);
  ASSERT_EQ(cudaMemcpy(b, host.data(), 1000, cudaMemcpyHostToDevice), cudaSuccess);
  ASSERT_EQ(cudaMemcpy(back.data(), b, 1000, cudaMemcpyDeviceToHost), cudaSuccess);
  EXPECT_EQ(back, host);
  resources.FreeDevice(a);
  resources.FreeDevice(b);
}

// The budget holds on the device: cached blocks go back (cudaFree) to make
// room, and blocks in use past it are a DeviceMemoryError.
TEST(GpuResources, TheBudgetTrimsTheCacheThenRefuses) {
  SKIP_WITHOUT_CUDA_DEVICE();
  constexpr size_t kMiB = size_t{1} << 20;
  cuda::GpuResources resources(0, 64 * kMiB);
  EXPECT_EQ(resources.ScratchBytes(), 2 * kMiB);
  void* big = resources.AllocateDevice(40 * kMiB, "big");
  resources.FreeDevice(big);
  void* other = resources.AllocateDevice(30 * kMiB, "other");  // 40 + 30 > 64: the cached 40 MiB go
  EXPECT_EQ(resources.DeviceStats().trimmed_blocks, 1u);
  EXPECT_LE(resources.DeviceStats().peak_held_bytes, 64 * kMiB);
  EXPECT_THROW(resources.AllocateDevice(40 * kMiB, "too much"), DeviceMemoryError);
  resources.FreeDevice(other);
}

TEST(GpuResources, PinnedBlocksAreMappedAndReused) {
  SKIP_WITHOUT_CUDA_DEVICE();
  cuda::GpuResources resources(0, 0);
  cuda::PinnedBuffer buffer;
  buffer.Allocate(&resources, 4096, "test");
  ASSERT_NE(buffer.host<int>(), nullptr);
  ASSERT_NE(buffer.device<int>(), nullptr);
  void* first = buffer.host<void>();
  buffer.Release();
  buffer.Allocate(&resources, 4000, "test");
  EXPECT_EQ(buffer.host<void>(), first);
  EXPECT_EQ(resources.PinnedStats().reuses, 1u);
  EXPECT_EQ(resources.DeviceStats().source_allocations, 0u) << "pinned memory is not device memory";
}

TEST(PinnedUploadRing, MoreUploadsThanSlotsArriveIntact) {
  SKIP_WITHOUT_CUDA_DEVICE();
  cudaStream_t stream = nullptr;
  ASSERT_EQ(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking), cudaSuccess);
  cuda::GpuResources resources(0, 0);
  std::vector<void*> blocks;
  std::vector<std::vector<uint8_t>> sent;
  {
    cuda::PinnedUploadRing ring(&resources);
    for (int k = 0; k < 3 * cuda::PinnedUploadRing::kSlots + 1; ++k) {
      const size_t bytes = 1000 + 4096 * static_cast<size_t>(k % 3);  // slots grow and are reused
      std::vector<uint8_t> host(bytes);
      for (size_t i = 0; i < bytes; ++i) host[i] = static_cast<uint8_t>(31 * k + i);
      sent.push_back(host);
      blocks.push_back(resources.AllocateDevice(bytes, "test"));
      ring.Upload(host.data(), bytes, blocks.back(), stream);
      host.assign(bytes, 0xff);  // the ring has its own copy: the caller's may change at once
    }
  }
  ASSERT_EQ(cudaStreamSynchronize(stream), cudaSuccess);
  for (size_t k = 0; k < blocks.size(); ++k) {
    std::vector<uint8_t> back(sent[k].size());
    ASSERT_EQ(cudaMemcpy(back.data(), blocks[k], back.size(), cudaMemcpyDeviceToHost), cudaSuccess);
    EXPECT_EQ(back, sent[k]) << "upload " << k;
    resources.FreeDevice(blocks[k]);
  }
  cudaStreamDestroy(stream);
}

// Both GPU backends keep their images in a pool and upload them staged.
class GpuImages : public ::testing::TestWithParam<MatcherType> {};

TEST_P(GpuImages, ImagesAddedAgainAfterRemovalMatchAsBefore) {
  SKIP_WITHOUT_CUDA_DEVICE();
  std::mt19937 rng(11);
  std::vector<std::vector<uint8_t>> base;
  for (int k = 0; k < 600; ++k) base.push_back(testing_support::RandomSift(&rng));
  std::uniform_int_distribution<int> noise(-4, 4);
  std::vector<FeatureDescriptors> images(6);
  for (FeatureDescriptors& d : images) {
    for (const std::vector<uint8_t>& b : base) {
      for (uint8_t x : b) d.data.push_back(static_cast<uint8_t>(std::clamp(int(x) + noise(rng), 0, 255)));
    }
  }
  std::vector<const FeatureDescriptors*> pointers;
  for (const FeatureDescriptors& d : images) pointers.push_back(&d);
  const MeanDescriptor mean = ComputeMeanDescriptor(pointers);
  std::vector<ImagePair> pairs;
  for (image_t i = 0; i < 6; ++i)
    for (image_t j = i + 1; j < 6; ++j) pairs.emplace_back(i, j);

  CasHashOptions cashash = CascadeOptions();
  cashash.matcher = GetParam();
  auto matcher = cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), cashash, mean, 0);
  for (image_t i = 0; i < 6; ++i) matcher->AddImage(i, images[i]);
  const std::vector<FeatureMatches> first = matcher->Match(pairs);
  size_t total = 0;
  for (const FeatureMatches& m : first) total += m.size();
  ASSERT_GT(total, 1000u);
  // Remove half, add them back in another order (recycled blocks), plus a
  // shared handle for one of them.
  for (image_t i : {1u, 3u, 5u}) matcher->RemoveImage(i);
  matcher->AddImage(5, images[5]);
  matcher->AddImage(MatcherImage{1, nullptr, std::make_shared<const FeatureDescriptors>(images[1])});
  matcher->AddImage(3, images[3]);
  EXPECT_EQ(matcher->Match(pairs), first);
}

INSTANTIATE_TEST_SUITE_P(Backends, GpuImages, ::testing::Values(MatcherType::kCascade, MatcherType::kBruteForce));

}  // namespace
}  // namespace cashash
