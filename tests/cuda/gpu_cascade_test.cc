// GPU Cascade Hashing against the CPU cascade reference: the hash bits are
// exact integers on both, so the matches must agree except for float
// rounding in the acceptance test. Skipped when no CUDA device is usable.
#include <gtest/gtest.h>

#include "gpu_test_support.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "cashash/base/device_memory_error.h"
#include "cashash/matchers/feature_matcher.h"
#include "cashash/pipeline/exact_rematch_stage.h"
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/device_memory.cuh"
#include "cascade_options.h"

namespace cashash {
namespace {

using testing_support::CascadeOptions;

// Descriptor source: synthetic SIFT-like rows (sparse, L2 norm ~512), the
// same on every machine for the same seed.
class DescriptorSource {
 public:
  explicit DescriptorSource(uint32_t seed) : rng_(seed) {}

  void Row(uint8_t* out) {
    std::normal_distribution<float> normal(0.f, 1.f);
    std::bernoulli_distribution on(0.6);
    float v[kDescriptorDim];
    double norm = 0;
    for (int d = 0; d < kDescriptorDim; ++d) {
      v[d] = on(rng_) ? std::exp(0.9f * normal(rng_)) : 0.f;
      norm += double(v[d]) * v[d];
    }
    const float scale = norm > 0 ? static_cast<float>(512.0 / std::sqrt(norm)) : 0.f;
    for (int d = 0; d < kDescriptorDim; ++d) out[d] = static_cast<uint8_t>(std::min(255.f, std::round(v[d] * scale)));
  }

  // A noisy copy of `in`, as the same point seen in another image.
  void Perturb(const uint8_t* in, uint8_t* out, float sigma) {
    std::normal_distribution<float> noise(0.f, sigma);
    for (int d = 0; d < kDescriptorDim; ++d) {
      out[d] = static_cast<uint8_t>(std::clamp(std::round(in[d] + noise(rng_)), 0.f, 255.f));
    }
  }

  FeatureDescriptors Image(size_t n) {
    FeatureDescriptors f;
    f.data.resize(n * kDescriptorDim);
    for (size_t i = 0; i < n; ++i) Row(f.data.data() + i * kDescriptorDim);
    return f;
  }

  // An image sharing `overlap` of its features (noisy, shuffled) with `base`.
  FeatureDescriptors Related(const FeatureDescriptors& base, size_t n, double overlap) {
    FeatureDescriptors f = Image(n);
    std::vector<size_t> order(base.rows());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::shuffle(order.begin(), order.end(), rng_);
    const size_t shared = std::min(order.size(), static_cast<size_t>(overlap * n));
    std::vector<size_t> slots(n);
    for (size_t i = 0; i < n; ++i) slots[i] = i;
    std::shuffle(slots.begin(), slots.end(), rng_);
    for (size_t i = 0; i < shared; ++i) {
      Perturb(base.row(order[i]), f.data.data() + slots[i] * kDescriptorDim, 6.f);
    }
    return f;
  }

 private:
  std::mt19937 rng_;
};

MeanDescriptor MeanOf(const std::vector<FeatureDescriptors>& images) {
  std::vector<const FeatureDescriptors*> ptrs;
  for (const auto& image : images) ptrs.push_back(&image);
  return ComputeMeanDescriptor(ptrs);
}

std::vector<ImagePair> AllPairs(size_t num_images) {
  std::vector<ImagePair> pairs;
  for (image_t i = 0; i < num_images; ++i) {
    for (image_t j = i + 1; j < num_images; ++j) pairs.emplace_back(i, j);
  }
  return pairs;
}

std::vector<FeatureMatches> AddAndMatch(FeatureMatcher* matcher, const std::vector<FeatureDescriptors>& images,
                                const std::vector<ImagePair>& pairs) {
  for (size_t i = 0; i < images.size(); ++i) matcher->AddImage(static_cast<image_t>(i), images[i]);
  return matcher->Match(pairs);
}

struct Agreement {
  size_t cpu = 0, gpu = 0, common = 0;
  double value() const { return std::max(cpu, gpu) == 0 ? 1.0 : double(common) / double(std::max(cpu, gpu)); }
};

Agreement Compare(const std::vector<FeatureMatches>& cpu, const std::vector<FeatureMatches>& gpu) {
  Agreement a;
  EXPECT_EQ(cpu.size(), gpu.size());
  for (size_t p = 0; p < std::min(cpu.size(), gpu.size()); ++p) {
    std::set<std::pair<uint32_t, uint32_t>> reference;
    for (const FeatureMatch& m : cpu[p]) reference.emplace(m.point2D_idx1, m.point2D_idx2);
    a.cpu += cpu[p].size();
    a.gpu += gpu[p].size();
    for (const FeatureMatch& m : gpu[p]) a.common += reference.count({m.point2D_idx1, m.point2D_idx2});
    // Matches come sorted by idx1 like the CPU backend's.
    EXPECT_TRUE(std::is_sorted(gpu[p].begin(), gpu[p].end())) << "pair " << p;
  }
  return a;
}

Agreement CompareWithCpu(const std::vector<FeatureDescriptors>& images, const std::vector<ImagePair>& pairs,
                         const SiftMatchingOptions& sift, const CasHashOptions& cas) {
  const MeanDescriptor mean = MeanOf(images);
  auto cpu = CreateCpuFeatureMatcher(sift, cas, mean);
  auto gpu = cuda::CreateGpuFeatureMatcher(sift, cas, mean, 0);
  const Agreement a = Compare(AddAndMatch(cpu.get(), images, pairs), AddAndMatch(gpu.get(), images, pairs));
  std::printf("[ agreement ] %s: cpu %zu, gpu %zu, common %zu -> %.4f%%\n", gpu->Name().c_str(), a.cpu, a.gpu,
              a.common, 100.0 * a.value());
  return a;
}

TEST(GpuCascadeTest, AgreesWithCpuCascade) {
  SKIP_WITHOUT_CUDA_DEVICE();
  DescriptorSource source(1);
  std::vector<FeatureDescriptors> images{source.Image(4000)};
  for (int i = 1; i < 6; ++i) images.push_back(source.Related(images[i - 1], 3000 + 500 * i, 0.5));
  const Agreement a = CompareWithCpu(images, AllPairs(images.size()), SiftMatchingOptions(), CascadeOptions());
  EXPECT_GT(a.cpu, 1000u);  // the planted duplicates are found
  EXPECT_GE(a.value(), 0.995);
}

TEST(GpuCascadeTest, AgreesWithoutCrossCheckAndOtherParameters) {
  SKIP_WITHOUT_CUDA_DEVICE();
  DescriptorSource source(2);
  std::vector<FeatureDescriptors> images{source.Image(3000)};
  images.push_back(source.Related(images[0], 2500, 0.4));
  images.push_back(source.Related(images[1], 3500, 0.3));
  SiftMatchingOptions sift;
  sift.cross_check = false;
  CasHashOptions cas = CascadeOptions();
  cas.num_tables = 8;
  cas.bits_per_table = 7;
  cas.top_k = 32;
  cas.tau = 40;
  cas.random_seed = 7;
  const Agreement a = CompareWithCpu(images, AllPairs(images.size()), sift, cas);
  EXPECT_GT(a.cpu, 300u);
  EXPECT_GE(a.value(), 0.995);
}

TEST(GpuCascadeTest, SkewedBucketsAreNotTruncated) {
  SKIP_WITHOUT_CUDA_DEVICE();
  DescriptorSource source(3);
  FeatureDescriptors a = source.Image(6000), b = source.Related(a, 5000, 0.5);
  // 3000 identical rows in a and 2000 in b: one bucket of >= 2000 per table.
  std::vector<uint8_t> repeated(kDescriptorDim);
  source.Row(repeated.data());
  for (size_t i = 0; i < 3000; ++i) std::copy(repeated.begin(), repeated.end(), a.data.begin() + 2 * i * kDescriptorDim);
  for (size_t i = 0; i < 2000; ++i) std::copy(repeated.begin(), repeated.end(), b.data.begin() + 2 * i * kDescriptorDim);
  const std::vector<FeatureDescriptors> images{a, b};
  const Agreement agreement = CompareWithCpu(images, {{0, 1}, {1, 0}}, SiftMatchingOptions(), CascadeOptions());
  EXPECT_GT(agreement.cpu, 500u);
  EXPECT_GE(agreement.value(), 0.995);
}

TEST(GpuCascadeTest, EmptySingleAndLargeImages) {
  SKIP_WITHOUT_CUDA_DEVICE();
  DescriptorSource source(4);
  SiftMatchingOptions sift;
  sift.max_num_matches = 50000;
  std::vector<FeatureDescriptors> images{FeatureDescriptors(), source.Image(1), source.Image(41000)};
  images.push_back(source.Related(images[2], 40500, 0.3));
  // The single feature also appears (noisy) in the large image.
  source.Perturb(images[1].row(0), images[2].data.data() + 777 * kDescriptorDim, 2.f);
  const std::vector<ImagePair> pairs{{0, 2}, {2, 0}, {0, 1}, {1, 2}, {2, 1}, {2, 3}};
  const MeanDescriptor mean = MeanOf(images);
  auto cpu = CreateCpuFeatureMatcher(sift, CascadeOptions(), mean);
  auto gpu = cuda::CreateGpuFeatureMatcher(sift, CascadeOptions(), mean, 0);
  const auto cpu_matches = AddAndMatch(cpu.get(), images, pairs);
  const auto gpu_matches = AddAndMatch(gpu.get(), images, pairs);
  EXPECT_TRUE(gpu_matches[0].empty());
  EXPECT_TRUE(gpu_matches[1].empty());
  EXPECT_TRUE(gpu_matches[2].empty());
  EXPECT_EQ(gpu_matches[3], cpu_matches[3]);
  EXPECT_EQ(gpu_matches[4], cpu_matches[4]);
  const Agreement a = Compare(cpu_matches, gpu_matches);
  std::printf("[ agreement ] 41000 x 40500 features: cpu %zu, gpu %zu, common %zu\n", a.cpu, a.gpu, a.common);
  EXPECT_GT(gpu_matches[5].size(), 3000u);
  EXPECT_GE(a.value(), 0.995);
}

// The GPU matcher on device 0 with a memory budget of `budget_mib` MiB
// (0: none) and the given cascade kernels.
cuda::GpuMatcherConfig DeviceZero(size_t budget_mib = 0,
                                  cuda::GpuCascadeKernel kernel = cuda::GpuCascadeKernel::kBucketTiles) {
  cuda::GpuMatcherConfig config;
  config.gpu_index = 0;
  config.memory_budget_bytes = budget_mib << 20;
  config.cascade_kernel = kernel;
  return config;
}

// A chain of `num_images` related images (the first of `first` features,
// image i of base + step * i), and one descriptor repeated 400 times in the
// last two (every third row of one, every fifth of the other): buckets of
// 400 features and more, 13 chunks of A rows for a single tile warp.
std::vector<FeatureDescriptors> ChainWithRepeatedRows(uint32_t seed, int num_images, size_t first, size_t base,
                                                      size_t step) {
  DescriptorSource source(seed);
  std::vector<FeatureDescriptors> images{source.Image(first)};
  for (int i = 1; i < num_images; ++i) images.push_back(source.Related(images[i - 1], base + step * i, 0.5));
  std::vector<uint8_t> repeated(kDescriptorDim);
  source.Row(repeated.data());
  FeatureDescriptors& one = images[num_images - 2];
  FeatureDescriptors& other = images[num_images - 1];
  for (size_t i = 0; i < 400; ++i) {
    std::copy(repeated.begin(), repeated.end(), one.data.begin() + 3 * i * kDescriptorDim);
    std::copy(repeated.begin(), repeated.end(), other.data.begin() + 5 * i * kDescriptorDim);
  }
  return images;
}

TEST(GpuCascadeTest, MemoryBudgetSplitsBatchesOrFailsClearly) {
  SKIP_WITHOUT_CUDA_DEVICE();
  DescriptorSource source(5);
  std::vector<FeatureDescriptors> images{source.Image(3000)};
  for (int i = 1; i < 12; ++i) images.push_back(source.Related(images[i - 1], 3000, 0.4));
  const std::vector<ImagePair> pairs = AllPairs(images.size());
  const MeanDescriptor mean = MeanOf(images);
  // The budgets below are sized for 7 tables x 8 bits (the per-image bucket
  // tables grow with the number of tables), not for whatever the defaults are.
  CasHashOptions options = CascadeOptions();
  options.num_tables = 7;
  options.bits_per_table = 8;
  std::vector<FeatureMatches> unlimited;
  {
    auto gpu = cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), options, mean, 0);
    unlimited = AddAndMatch(gpu.get(), images, pairs);
  }
  {
    // ~1.05 MiB per image of 3000 features, ~6.2 MiB of candidate lists per
    // pair: 40 MiB leave scratch for about two pairs per batch, so the 66
    // pairs run in many batches.
    auto gpu = cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), options, mean, DeviceZero(40));
    EXPECT_EQ(AddAndMatch(gpu.get(), images, pairs), unlimited);
  }
  {
    auto gpu = cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), options, mean, DeviceZero(4));
    try {
      AddAndMatch(gpu.get(), images, pairs);
      ADD_FAILURE() << "12 images of 3000 features cannot fit in 4 MiB";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("budget"), std::string::npos) << e.what();
    }
  }
}

// The bucket-tile kernels (default) and the per-query kernel implement the
// same definition: identical matches, pair for pair, on real descriptors,
// with and without cross-check and with full candidate lists (skewed).
TEST(GpuCascadeTest, TiledAndPerQueryKernelsGiveIdenticalMatches) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const std::vector<FeatureDescriptors> images = ChainWithRepeatedRows(8, 5, 5000, 4000, 700);
  std::vector<ImagePair> pairs = AllPairs(images.size());
  pairs.emplace_back(4, 3);
  const MeanDescriptor mean = MeanOf(images);
  for (const bool cross_check : {true, false}) {
    for (const int top_k : {10, 20}) {
      SiftMatchingOptions sift;
      sift.cross_check = cross_check;
      CasHashOptions cas = CascadeOptions();
      cas.top_k = top_k;
      std::vector<FeatureMatches> direct, tiled;
      {
        auto gpu = cuda::CreateGpuFeatureMatcher(sift, cas, mean, DeviceZero(0, cuda::GpuCascadeKernel::kPerQuery));
        direct = AddAndMatch(gpu.get(), images, pairs);
      }
      {
        auto gpu = cuda::CreateGpuFeatureMatcher(sift, cas, mean, 0);
        tiled = AddAndMatch(gpu.get(), images, pairs);
      }
      size_t total = 0;
      for (const FeatureMatches& m : direct) total += m.size();
      std::printf("[ kernels ] cross_check %d, top_k %d: %zu matches, identical %d\n", cross_check ? 1 : 0, top_k,
                  total, direct == tiled ? 1 : 0);
      EXPECT_GT(total, 1000u);
      EXPECT_EQ(direct, tiled) << "cross_check " << cross_check << ", top_k " << top_k;
    }
  }
}

// Buckets of hundreds of features have their chunks past the first four
// shared out in a second pass (BigBucketQueue): the same candidates reach
// the (unordered) lists in another order, so the matches must be identical
// to the per-query kernel's.
TEST(GpuCascadeTest, BigBucketsSharedOutGiveThePerQueryKernelsMatches) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const std::vector<FeatureDescriptors> images = ChainWithRepeatedRows(9, 4, 6000, 5000, 500);
  const std::vector<ImagePair> pairs = AllPairs(images.size());
  const MeanDescriptor mean = MeanOf(images);
  SiftMatchingOptions sift;
  CasHashOptions cas = CascadeOptions();
  cas.num_tables = 6;
  cas.bits_per_table = 9;
  cas.tau = 32;
  std::vector<FeatureMatches> direct;
  {
    auto gpu = cuda::CreateGpuFeatureMatcher(sift, cas, mean, DeviceZero(0, cuda::GpuCascadeKernel::kPerQuery));
    direct = AddAndMatch(gpu.get(), images, pairs);
  }
  size_t total = 0;
  for (const FeatureMatches& m : direct) total += m.size();
  EXPECT_GT(total, 1000u);
  auto gpu = cuda::CreateGpuFeatureMatcher(sift, cas, mean, 0);
  EXPECT_EQ(AddAndMatch(gpu.get(), images, pairs), direct);
}

// cudaErrorMemoryAllocation becomes a DeviceMemoryError (recognised by its
// type, whatever the text), and the device stays usable afterwards.
TEST(GpuCascadeTest, DeviceOutOfMemoryIsADeviceMemoryError) {
  SKIP_WITHOUT_CUDA_DEVICE();
  cuda::GpuResources resources(0, 0);
  cuda::DeviceBuffer buffer;
  try {
    buffer.Allocate(&resources, size_t{1} << 50, "a petabyte");
    ADD_FAILURE() << "a petabyte was allocated";
  } catch (const DeviceMemoryError& e) {
    EXPECT_NE(std::string(e.what()).find("a petabyte"), std::string::npos) << e.what();
  }
  buffer.Allocate(&resources, 1 << 20, "a mebibyte");
  EXPECT_EQ(buffer.bytes(), size_t{1} << 20);
  void* raw = nullptr;
  EXPECT_THROW(CUDA_CHECK(cudaMalloc(&raw, size_t{1} << 50)), DeviceMemoryError);
}

TEST(GpuCascadeTest, BruteForceAgreesWithCpuBruteForce) {
  SKIP_WITHOUT_CUDA_DEVICE();
  DescriptorSource source(6);
  std::vector<FeatureDescriptors> images{source.Image(2000)};
  images.push_back(source.Related(images[0], 2500, 0.5));
  images.push_back(FeatureDescriptors());
  CasHashOptions cas = CascadeOptions();
  cas.matcher = MatcherType::kBruteForce;
  const Agreement a = CompareWithCpu(images, {{0, 1}, {1, 0}, {0, 2}}, SiftMatchingOptions(), cas);
  EXPECT_GT(a.cpu, 500u);
  EXPECT_GE(a.value(), 0.999);
}

// Images of different sizes, each sharing features with the one before,
// and an empty one: the pairs an exact rematch meets.
std::vector<FeatureDescriptors> ChainOfThreeAndAnEmptyImage(DescriptorSource* source) {
  std::vector<FeatureDescriptors> images{source->Image(3000)};
  images.push_back(source->Related(images[0], 2500, 0.5));
  images.push_back(source->Related(images[1], 4100, 0.3));
  images.push_back(FeatureDescriptors());
  return images;
}

// The cascade's exact matching (MatchExact, from the descriptors it
// uploaded) returns the GPU brute-force backend's matches, and those of the
// CPU brute force, on pairs whose images differ in size and on an empty one.
TEST(GpuCascadeTest, ExactMatchesOfTheCascadeEqualBruteForce) {
  SKIP_WITHOUT_CUDA_DEVICE();
  DescriptorSource source(7);
  const std::vector<FeatureDescriptors> images = ChainOfThreeAndAnEmptyImage(&source);
  const std::vector<ImagePair> pairs = {{0, 1}, {1, 0}, {1, 2}, {0, 2}, {0, 3}};
  const MeanDescriptor mean = MeanOf(images);
  CasHashOptions brute_force = CascadeOptions();
  brute_force.matcher = MatcherType::kBruteForce;
  auto cascade = cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), CascadeOptions(), mean, 0);
  auto gpu_brute_force = cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), brute_force, mean, 0);
  auto cpu_brute_force = CreateCpuFeatureMatcher(SiftMatchingOptions(), brute_force, mean);
  AddAndMatch(cascade.get(), images, {});
  const std::vector<FeatureMatches> exact = cascade->MatchExact(pairs);
  const std::vector<FeatureMatches> gpu = AddAndMatch(gpu_brute_force.get(), images, pairs);
  const std::vector<FeatureMatches> cpu = AddAndMatch(cpu_brute_force.get(), images, pairs);
  ASSERT_EQ(exact.size(), pairs.size());
  size_t total = 0;
  for (size_t p = 0; p < pairs.size(); ++p) {
    EXPECT_EQ(exact[p], gpu[p]) << "pair " << p;
    total += exact[p].size();
  }
  const Agreement a = Compare(cpu, exact);
  EXPECT_GT(total, 500u);
  EXPECT_TRUE(exact[4].empty());
  EXPECT_GE(a.value(), 0.999);
}

// Held images (HoldForExact) taken after a chunk is matched and matched on
// another thread, after the cascade has dropped those images and uploaded
// others into the blocks it reuses, give what MatchExact gave: the held
// matcher keeps the images' device blocks until it is let go.
TEST(GpuCascadeTest, HeldImagesAreMatchedLaterFromTheBlocksTheyHold) {
  SKIP_WITHOUT_CUDA_DEVICE();
  DescriptorSource source(11);
  const std::vector<FeatureDescriptors> images = ChainOfThreeAndAnEmptyImage(&source);
  const std::vector<ImagePair> pairs = {{0, 1}, {1, 2}, {0, 2}, {0, 3}};
  auto cascade = cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), CascadeOptions(), MeanOf(images), 0);
  AddAndMatch(cascade.get(), images, {});
  const std::vector<FeatureMatches> exact = cascade->MatchExact(pairs);
  std::unique_ptr<ExactMatcher> held = cascade->HoldForExact(pairs);
  ASSERT_NE(held, nullptr);
  // The cascade goes on: its images are replaced by others of the same sizes.
  std::vector<FeatureDescriptors> others;
  for (const FeatureDescriptors& d : images) others.push_back(source.Image(d.rows()));
  for (image_t id = 0; id < images.size(); ++id) cascade->RemoveImage(id);
  for (image_t id = 0; id < others.size(); ++id) cascade->AddImage(id + 10, others[id]);
  cascade->Match({{10, 11}, {11, 12}});
  std::vector<FeatureMatches> later;
  std::thread([&]() { later = held->MatchExact(pairs); }).join();
  held.reset();
  ASSERT_EQ(later.size(), exact.size());
  size_t total = 0;
  for (size_t p = 0; p < pairs.size(); ++p) {
    EXPECT_EQ(later[p], exact[p]) << "pair " << p;
    total += exact[p].size();
  }
  EXPECT_GT(total, 500u);
  EXPECT_TRUE(later[3].empty());
}

// The exact rematch stage on the GPU cascade: held on the matching thread
// and completed on another one after the images are gone, it gives what the
// rematch at once gives, and only the selected pairs change.
TEST(GpuCascadeTest, TheRematchStageFromHeldImagesEqualsTheRematchAtOnce) {
  SKIP_WITHOUT_CUDA_DEVICE();
  DescriptorSource source(13);
  const std::vector<FeatureDescriptors> images = ChainOfThreeAndAnEmptyImage(&source);
  const std::vector<ImagePair> pairs = {{0, 1}, {1, 2}, {0, 2}, {0, 3}};
  auto cascade = cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), CascadeOptions(), MeanOf(images), 0);
  ExactRematchPolicy policy;
  policy.min_matches = 12;
  policy.where = RematchPlace::kMatchingThread;
  ExactRematchStage at_once(policy, cascade.get());
  policy.where = RematchPlace::kVerificationThread;
  ExactRematchStage held(policy, cascade.get());
  const std::vector<FeatureMatches> cascade_matches = AddAndMatch(cascade.get(), images, pairs);
  std::vector<FeatureMatches> expected = cascade_matches;
  at_once.AfterMatching(pairs, &expected);
  std::vector<FeatureMatches> later = cascade_matches;
  PendingRematch pending = held.AfterMatching(pairs, &later);
  ASSERT_FALSE(pending.empty());
  for (image_t id = 0; id < images.size(); ++id) cascade->RemoveImage(id);
  std::thread([&]() {
    held.Complete(&pending, [](image_t) -> std::shared_ptr<const FeatureDescriptors> { return nullptr; }, &later);
  }).join();
  EXPECT_EQ(later, expected);
  EXPECT_EQ(held.counts().rematched.load(), at_once.counts().rematched.load());
  EXPECT_GE(held.counts().rematched.load(), 2u) << "the chained images' pairs";
  EXPECT_EQ(later[3], cascade_matches[3]) << "the empty image's pair keeps the cascade's (none)";
}

TEST(GpuCascadeTest, UnsupportedOptionsAreRejected) {
  SKIP_WITHOUT_CUDA_DEVICE();
  CasHashOptions cas = CascadeOptions();
  cas.top_k = 33;
  EXPECT_THROW(cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), cas, MeanDescriptor{}, 0), std::invalid_argument);
  cas = CascadeOptions();
  cas.num_tables = 10;
  cas.bits_per_table = 8;
  EXPECT_THROW(cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), cas, MeanDescriptor{}, 0), std::invalid_argument);
}

// The shape the table rule gives the GPU at 16,384 features and more
// (table_shape.h; the CPU alone takes finer buckets there): 8 tables of 8
// bits fill the 64-bit signature exactly. Same matches as the CPU with the
// same shape, as for every other shape.
TEST(GpuCascadeTest, SixtyFourSignatureBitsOfTheTableRuleAgreeWithCpu) {
  SKIP_WITHOUT_CUDA_DEVICE();
  DescriptorSource source(5);
  std::vector<FeatureDescriptors> images{source.Image(16384)};
  images.push_back(source.Related(images[0], 16384, 0.5));
  images.push_back(source.Related(images[1], 16384, 0.5));
  CasHashOptions cas = CascadeOptions();
  cas.num_tables = 8;
  cas.bits_per_table = 8;
  const Agreement a = CompareWithCpu(images, AllPairs(images.size()), SiftMatchingOptions(), cas);
  EXPECT_GT(a.cpu, 1000u);
  EXPECT_EQ(a.common, a.cpu);
  EXPECT_EQ(a.common, a.gpu);
}

// The values a run chooses (matcher auto, tau 0, rematch threshold -1) are
// decided from the run's data before a matcher is built (ResolveRun): the
// GPU factory refuses them, naming the option, before touching a device, so
// that no run can match with a choice nobody made.
TEST(GpuCascadeTest, ValuesChosenForTheRunAreRefusedUndecided) {
  DescriptorSource source(6);
  const std::vector<FeatureDescriptors> images{source.Image(300)};
  CasHashOptions automatic = CascadeOptions();
  automatic.matcher = MatcherType::kAuto;
  CasHashOptions tau = CascadeOptions();
  tau.tau = kTauChosen;
  CasHashOptions rematch = CascadeOptions();
  rematch.exact_rematch_min_matches = kRematchMinMatchesChosen;
  const std::pair<CasHashOptions, const char*> cases[] = {{automatic, "--CasHash.matcher auto"},
                                                          {tau, "--CasHash.tau 0"},
                                                          {rematch, "--CasHash.exact_rematch_min_matches -1"}};
  for (const auto& [cas, option] : cases) {
    try {
      cuda::CreateGpuFeatureMatcher(SiftMatchingOptions(), cas, MeanOf(images), 0);
      ADD_FAILURE() << "built a GPU matcher with " << option;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(option), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace cashash
