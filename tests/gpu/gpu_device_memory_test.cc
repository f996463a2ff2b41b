// The device block pool that holds the GPU matcher's images, and the
// matcher's images through it: blocks are reused by size, and images added
// again after removal (their blocks recycled, their uploads staged through
// pinned memory without a wait) match as before.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "../synthetic_sift.h"
#include "cashash/feature_matcher.h"
#include "gpu_test_support.h"
#include "impl/device_memory.cuh"

namespace cashash {
namespace {

TEST(DeviceBlockPool, BlocksAreDistinctAlignedAndReusedBySize) {
  SKIP_WITHOUT_CUDA_DEVICE();
  cuda::DeviceBlockPool pool;
  char* a = static_cast<char*>(pool.Acquire(1000, "test"));
  char* b = static_cast<char*>(pool.Acquire(1000, "test"));
  EXPECT_NE(a, b);
  EXPECT_GE(static_cast<size_t>(std::max(a, b) - std::min(a, b)), 1000u);  // no overlap
  EXPECT_EQ(reinterpret_cast<uintptr_t>(b) % cuda::DeviceBlockPool::kAlignment, 0u);
  pool.Release(a, 1000);
  EXPECT_EQ(pool.Acquire(1000, "test"), a);  // same size: the freed block
  void* big = pool.Acquire(cuda::DeviceBlockPool::kChunkBytes + 1, "test");  // a chunk of its own
  EXPECT_NE(big, nullptr);
  // Blocks are device memory: a round trip through one of them.
  std::vector<int> host(250, 7), back(250, 0);
  ASSERT_EQ(cudaMemcpy(b, host.data(), 1000, cudaMemcpyHostToDevice), cudaSuccess);
  ASSERT_EQ(cudaMemcpy(back.data(), b, 1000, cudaMemcpyDeviceToHost), cudaSuccess);
  EXPECT_EQ(back, host);
}

TEST(GpuCascadeImages, ImagesAddedAgainAfterRemovalMatchAsBefore) {
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

  auto matcher = cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), CasHashOptions(), mean, 0);
  for (image_t i = 0; i < 6; ++i) matcher->AddImage(i, images[i]);
  const std::vector<FeatureMatches> first = matcher->MatchPairs(pairs);
  size_t total = 0;
  for (const FeatureMatches& m : first) total += m.size();
  ASSERT_GT(total, 1000u);
  // Remove half, add them back in another order (recycled blocks), plus a
  // shared handle for one of them.
  for (image_t i : {1u, 3u, 5u}) matcher->RemoveImage(i);
  matcher->AddImage(5, images[5]);
  matcher->AddSharedImage(1, std::make_shared<const FeatureDescriptors>(images[1]));
  matcher->AddImage(3, images[3]);
  EXPECT_EQ(matcher->MatchPairs(pairs), first);
}

}  // namespace
}  // namespace cashash
