// Block and group sizes from the memory caps, and the cap holding when the
// sizes drive the feature cache under the pipeline.
#include "cashash/pipeline/schedule_sizing.h"

#include <map>
#include <stdexcept>

#include <gtest/gtest.h>

#include "cashash/pipeline/feature_cache.h"
#include "cashash/pipeline/pair_generation.h"

namespace cashash {
namespace {

constexpr size_t kMiB = size_t{1} << 20;
constexpr size_t kGiB = size_t{1} << 30;

TEST(ScheduleSizing, ParsesMemorySizes) {
  size_t bytes = 0;
  ASSERT_TRUE(ParseMemorySize("4096", &bytes));
  EXPECT_EQ(bytes, 4096 * kMiB);
  ASSERT_TRUE(ParseMemorySize("16G", &bytes));
  EXPECT_EQ(bytes, 16 * kGiB);
  ASSERT_TRUE(ParseMemorySize("1.5g", &bytes));
  EXPECT_EQ(bytes, 3 * kGiB / 2);
  ASSERT_TRUE(ParseMemorySize("512MB", &bytes));
  EXPECT_EQ(bytes, 512 * kMiB);
  ASSERT_TRUE(ParseMemorySize("2GiB", &bytes));
  EXPECT_EQ(bytes, 2 * kGiB);
  ASSERT_TRUE(ParseMemorySize("800K", &bytes));
  EXPECT_EQ(bytes, 800 * size_t{1024});
  for (const char* bad : {"", "G", "12X", "-1G", "0", "abc", "1.5.2G"}) {
    EXPECT_FALSE(ParseMemorySize(bad, &bytes)) << bad;
  }
  EXPECT_GT(PhysicalMemoryBytes(), 0u);
  EXPECT_EQ(FormatMemorySize(3 * kGiB / 2), "1.5 GiB");
  EXPECT_EQ(FormatMemorySize(512 * kMiB), "512 MiB");
}

TEST(ScheduleSizing, AmpleMemoryKeepsColmapBlocksAndOneGroup) {
  ScheduleLimits limits;
  limits.max_host_bytes = 64 * kGiB;
  const ScheduleSizes sizes = ChooseScheduleSizes(std::vector<size_t>(300, 12000), limits);
  EXPECT_EQ(sizes.block_size, 50);
  EXPECT_EQ(sizes.blocks_per_group, 6);  // all 300 images in one group
  EXPECT_LE(sizes.predicted_host_bytes, limits.max_host_bytes);
  EXPECT_TRUE(sizes.warning.empty());
}

TEST(ScheduleSizing, KeptImagesHostMemoryIsPlannedWithinTheHostCap) {
  // The host copies of the images a GPU run keeps come on top of the cache
  // and the pipeline: the schedule names them, bounded by the images there
  // are and, with the prediction, by the host cap.
  const std::vector<size_t> features(5000, 8192);
  const size_t host_copy = 8192 * 128 + 1024;
  ScheduleLimits limits;
  limits.max_host_bytes = 16 * kGiB;
  limits.max_gpu_bytes = 139 * kGiB;
  const ScheduleSizes all = ChooseScheduleSizes(features, limits);
  // Every image beyond the 200 in use (4 blocks of 50), once.
  EXPECT_EQ(all.kept_host_bytes, (5000 - 4 * all.block_size) * host_copy);
  EXPECT_LE(all.predicted_host_bytes + all.kept_host_bytes, limits.max_host_bytes);
  // A tighter host cap, which the cache's three groups of 2,000 images do
  // not fill, keeps fewer copies, still within it.
  limits.max_host_bytes = 12 * kGiB;
  const ScheduleSizes few = ChooseScheduleSizes(features, limits);
  EXPECT_GT(few.kept_host_bytes, 0u);
  EXPECT_LT(few.kept_host_bytes, all.kept_host_bytes);
  EXPECT_LE(few.predicted_host_bytes + few.kept_host_bytes, limits.max_host_bytes);
  // On the CPU the kept images are the matcher's own, within the cap too.
  limits.max_gpu_bytes = 0;
  limits.max_host_bytes = 16 * kGiB;
  const ScheduleSizes cpu = ChooseScheduleSizes(features, limits);
  EXPECT_LE(cpu.predicted_host_bytes + cpu.kept_host_bytes, limits.max_host_bytes);
}

TEST(ScheduleSizing, GpuRunKeepsEveryImageWhenTheDeviceHoldsThem) {
  // 5000 images of 8192 features, 16 GiB of host memory, a 139 GiB GPU: the
  // device holds every image's tables (3.1 MB each) and the host the CPU
  // fallback's copies of their descriptors (1 MB each), so every image is
  // hashed once.
  const std::vector<size_t> features(5000, 8192);
  ScheduleLimits limits;
  limits.max_host_bytes = 16 * kGiB;
  limits.max_gpu_bytes = 139 * kGiB;
  const ScheduleSizes sizes = ChooseScheduleSizes(features, limits);
  EXPECT_GE(sizes.matcher_keep_bytes, 5000 * sizes.matcher_bytes_per_image);
  // Kept descriptors and the predicted host use stay within the host cap.
  const size_t kept = sizes.matcher_keep_bytes / sizes.matcher_bytes_per_image;
  EXPECT_LE(sizes.predicted_host_bytes + kept * (8192 * 128 + 1024), limits.max_host_bytes);
  // Without a GPU the same images cost host memory: far fewer are kept.
  limits.max_gpu_bytes = 0;
  const ScheduleSizes cpu = ChooseScheduleSizes(features, limits);
  EXPECT_LT(cpu.matcher_keep_bytes, sizes.matcher_keep_bytes / 2);
}

TEST(ScheduleSizing, GroupsAndTheCpuMatchersKeepDoNotGrowWithTheCollection) {
  // Few features an image and the default cap (half of a 24 GiB machine):
  // every image would fit in one group, but groups stop at kMaxGroupImages,
  // and the CPU matcher keeps no more images than the cache's groups hold,
  // so 20,000 images hold what 8,000 do (and 5,000 a little less: all
  // their images fit in three groups).
  ScheduleLimits limits;
  limits.max_host_bytes = 12 * kGiB;
  const ScheduleSizes small = ChooseScheduleSizes(std::vector<size_t>(8000, 8), limits);
  const ScheduleSizes large = ChooseScheduleSizes(std::vector<size_t>(20000, 8), limits);
  for (const ScheduleSizes* sizes : {&small, &large}) {
    EXPECT_EQ(sizes->block_size, 50);
    EXPECT_EQ(static_cast<size_t>(sizes->blocks_per_group * sizes->block_size), kMaxGroupImages);
  }
  EXPECT_EQ(large.matcher_keep_bytes, small.matcher_keep_bytes);
  EXPECT_EQ(large.predicted_host_bytes, small.predicted_host_bytes);
  // At most the cache's three groups, and more than the two a group pair uses.
  EXPECT_LE(large.matcher_keep_bytes, kCacheGroups * kMaxGroupImages * large.matcher_bytes_per_image);
  EXPECT_GT(large.matcher_keep_bytes, 2 * kMaxGroupImages * large.matcher_bytes_per_image);
  // A collection smaller than a group is one group, every image kept.
  const ScheduleSizes one = ChooseScheduleSizes(std::vector<size_t>(1000, 8), limits);
  EXPECT_EQ(one.blocks_per_group, 20);
  EXPECT_GE(one.matcher_keep_bytes, 1000 * one.matcher_bytes_per_image * 8 / 10);
}

TEST(ScheduleSizing, HostCapMakesGroupsSmaller) {
  const std::vector<size_t> features(3000, 12000);  // 1.8 MB of features per image
  ScheduleLimits limits;
  limits.max_host_bytes = 4 * kGiB;
  const ScheduleSizes sizes = ChooseScheduleSizes(features, limits);
  EXPECT_EQ(sizes.block_size, 50);
  EXPECT_GE(sizes.blocks_per_group, 1);
  EXPECT_LT(sizes.blocks_per_group, 60);  // 60 blocks would be every image
  EXPECT_LE(sizes.predicted_host_bytes, limits.max_host_bytes);
  // One block more per group would not fit.
  const size_t more = sizes.predicted_host_bytes + 3 * 50 * sizes.host_bytes_per_image;
  EXPECT_GT(more, limits.max_host_bytes);
}

TEST(ScheduleSizing, GpuCapMakesBlocksSmaller) {
  const std::vector<size_t> features(500, 20000);
  ScheduleLimits limits;
  limits.max_host_bytes = 64 * kGiB;
  limits.max_gpu_bytes = 512 * kMiB;
  const ScheduleSizes sizes = ChooseScheduleSizes(features, limits);
  EXPECT_LT(sizes.block_size, 50);
  EXPECT_GE(sizes.block_size, 2);
  EXPECT_LE(sizes.predicted_gpu_bytes, static_cast<size_t>(limits.gpu_image_share * limits.max_gpu_bytes));
  EXPECT_TRUE(sizes.warning.empty());
}

TEST(ScheduleSizing, UserBlockSizeIsKeptWithAWarningWhenTheGpuCannotHoldIt) {
  ScheduleLimits limits;
  limits.max_host_bytes = 64 * kGiB;
  limits.max_gpu_bytes = 256 * kMiB;
  limits.block_size = 200;
  const ScheduleSizes sizes = ChooseScheduleSizes(std::vector<size_t>(500, 20000), limits);
  EXPECT_EQ(sizes.block_size, 200);
  EXPECT_NE(sizes.warning.find("GPU memory"), std::string::npos) << sizes.warning;
}

TEST(ScheduleSizing, LargestImageSetsTheSizes) {
  std::vector<size_t> features(400, 1000);
  ScheduleLimits limits;
  limits.max_host_bytes = 2 * kGiB;
  const ScheduleSizes small = ChooseScheduleSizes(features, limits);
  features[123] = 30000;
  const ScheduleSizes large = ChooseScheduleSizes(features, limits);
  EXPECT_EQ(large.host_bytes_per_image, HostBytesPerImage(30000));
  EXPECT_LT(large.blocks_per_group, small.blocks_per_group);
}

TEST(ScheduleSizing, TooLittleHostMemoryIsAnError) {
  ScheduleLimits limits;
  limits.max_host_bytes = 8 * kMiB;
  try {
    ChooseScheduleSizes(std::vector<size_t>(100, 20000), limits);
    FAIL() << "accepted 8 MiB";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("--max_host_memory"), std::string::npos) << e.what();
  }
}

// Images of varying size (2000 to 9000 features) read through the cache under
// the pipeline with sizes chosen for a 150 MiB cap: the features the cache
// and the pipeline hold together never pass the cap.
class SizedSource : public FeatureSource {
 public:
  explicit SizedSource(const std::vector<size_t>& features) : features_(features) {}
  ImageFeatures LoadFeatures(image_t image_id) override {
    ImageFeatures f;
    f.image_id = image_id;
    f.keypoints.resize(features_.at(image_id - 1));
    f.descriptors.data.assign(f.keypoints.size() * kDescriptorDim, 1);
    ++reads;
    return f;
  }
  const Camera& CameraOfImage(image_t) const override { return camera_; }
  size_t reads = 0;

 private:
  std::vector<size_t> features_;
  Camera camera_;
};

class NullMatcher : public FeatureMatcher {
 public:
  NullMatcher() : FeatureMatcher(MatcherTraits{"null"}) {}
  void AddImage(const Image&) override {}
  void RemoveImage(image_t) override {}
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& = {}) override {
    return std::vector<FeatureMatches>(pairs.size());
  }
};

class CountingSink : public ResultSink {
 public:
  void WriteChunk(const std::vector<PairResult>& results) override { pairs += results.size(); }
  size_t pairs = 0;
};

TEST(ScheduleSizing, CapRespectedThroughTheCache) {
  std::vector<size_t> features;
  std::vector<image_t> ids;
  for (size_t i = 0; i < 120; ++i) {
    features.push_back(2000 + (i * 7919) % 7001);
    ids.push_back(static_cast<image_t>(i + 1));
  }
  ScheduleLimits limits;
  limits.max_host_bytes = 150 * kMiB;
  limits.max_gpu_bytes = 1 * kGiB;  // matcher off the host
  const ScheduleSizes sizes = ChooseScheduleSizes(features, limits);
  ASSERT_GT(sizes.blocks_per_group, 0);
  const std::vector<PairChunk> chunks = ScheduledPairChunks(ids, sizes.block_size, sizes.blocks_per_group);
  ASSERT_GT(chunks.front().num_groups, 1) << "the cap should force several groups";

  SizedSource source(features);
  GroupFeatureCache cache(&source, chunks);
  NullMatcher matcher;
  CountingSink sink;
  PipelineOptions options;
  options.skip_geometric_verification = true;
  MatchingPipeline pipeline(options, &cache, &matcher, &sink);
  pipeline.Run(chunks);
  EXPECT_EQ(sink.pairs, ids.size() * (ids.size() - 1) / 2);
  const size_t pipeline_bytes = kPipelineBlocks * sizes.block_size * sizes.host_bytes_per_image;
  EXPECT_LE(cache.stats().peak_bytes + pipeline_bytes, limits.max_host_bytes);
  EXPECT_LE(cache.stats().peak_bytes, kCacheGroups * sizes.blocks_per_group * sizes.block_size * sizes.host_bytes_per_image);
  std::cout << "120 images, cap 150 MiB: blocks of " << sizes.block_size << ", " << sizes.blocks_per_group
            << " blocks per group, " << chunks.front().num_groups << " groups, cache peak "
            << FormatMemorySize(cache.stats().peak_bytes) << ", " << source.reads << " reads for 120 images"
            << std::endl;
}

}  // namespace
}  // namespace cashash
