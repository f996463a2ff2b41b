// The GPU's TopK over the retrieval index (cuda/cashash_cuda/retrieval/
// image_retrieval_index.h) against the CPU's: the same neighbours, up to
// the order of images whose scores lie within the rounding of either sum;
// the same on every run; tiles of images, subsets of queries, k past the
// images, images sharing no word, and a budget without room.
#include "cashash_cuda/retrieval/image_retrieval_index.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <vector>

#include "cashash/base/device_memory_error.h"
#include "cashash/retrieval/image_retrieval_index.h"
#include "cashash/retrieval/visual_words.h"
#include "cashash_cuda/utils/gpu_resources.h"
#include "gpu_test_support.h"

namespace cashash {
namespace {

// What two scores of one image pair may differ by: the GPU's sum rounds
// each term to half a step (a few thousand terms at most here), the CPU's
// float sum rounds as it goes; both far below the gaps that decide ranks.
constexpr double kScoreTolerance = 1e-5;

using Lists = std::vector<std::vector<RetrievalNeighbor>>;

// Words of `images` images, each `words_per_image` words drawn from a
// vocabulary of `vocabulary` words (a random collection: overlaps by
// chance only).
std::vector<ImageWords> RandomImages(size_t images, size_t words_per_image, uint32_t vocabulary, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<ImageWords> result(images);
  for (ImageWords& image : result) {
    for (size_t w = 0; w < words_per_image; ++w) image.indexed.push_back(static_cast<uint32_t>(rng() % vocabulary));
  }
  return result;
}

// A street as retrieval sees it: image i sees points of street units
// [i, i + 10), each point a word per table (of 2^bits cells), 30 % of its
// words lost to noise and replaced by chance words, and query words
// spread to a second cell half the time (the multi-probe query side).
std::vector<ImageWords> StreetImages(size_t images, size_t features, int tables, int bits, uint64_t seed,
                                     uint32_t* vocabulary) {
  constexpr uint64_t kWindow = 10;
  const uint64_t cells = uint64_t{1} << bits;
  const uint64_t points_per_unit = std::max<uint64_t>(1, features * 2 / kWindow);
  *vocabulary = static_cast<uint32_t>(cells * static_cast<uint64_t>(tables));
  std::vector<ImageWords> result(images);
  for (size_t i = 0; i < images; ++i) {
    std::mt19937_64 rng(seed * 1000003 + i);
    ImageWords& image = result[i];
    for (size_t f = 0; f < features; ++f) {
      const uint64_t unit = i + rng() % kWindow;
      const uint64_t point = unit * points_per_unit + rng() % points_per_unit;
      for (int t = 0; t < tables; ++t) {
        uint64_t cell = (point * 0x9E3779B97F4A7C15ull + static_cast<uint64_t>(t) * 0xBF58476D1CE4E5B9ull) >> 17;
        if (rng() % 10 < 3) cell = rng();
        const uint32_t word = static_cast<uint32_t>(static_cast<uint64_t>(t) * cells + cell % cells);
        image.indexed.push_back(word);
        image.query.push_back(word);
        if (rng() % 2 == 0) image.query.push_back(static_cast<uint32_t>(t * cells + (cell ^ 1u) % cells));
      }
    }
  }
  return result;
}

// The exact (double) cosine of query image q with image j, from the view.
double ExactScore(const RetrievalIndexView& view, size_t q, uint32_t j) {
  double score = 0;
  for (size_t w = view.query_offsets[q]; w < view.query_offsets[q + 1]; ++w) {
    const RetrievalQueryWord& word = view.queries[w];
    const RetrievalPosting* begin = view.postings + view.posting_offsets[word.word];
    const RetrievalPosting* end = view.postings + view.posting_offsets[word.word + 1];
    const RetrievalPosting* at =
        std::lower_bound(begin, end, j, [](const RetrievalPosting& p, uint32_t image) { return p.image < image; });
    if (at != end && at->image == j) score += static_cast<double>(word.weight) * at->weight;
  }
  return score;
}

// The GPU's lists against the CPU's: same lengths, every GPU score the
// exact cosine, rank by rank the same scores, and images that differ only
// where the CPU's scores lie within the tolerance of each other. Returns
// the share of lists that are identical.
double CompareWithCpu(const RetrievalIndexView& view, const Lists& gpu, const Lists& cpu, size_t k) {
  EXPECT_EQ(gpu.size(), cpu.size());
  size_t identical = 0;
  for (size_t i = 0; i < gpu.size() && i < cpu.size(); ++i) {
    EXPECT_EQ(gpu[i].size(), cpu[i].size()) << "image " << i;
    EXPECT_LE(gpu[i].size(), k);
    if (gpu[i].size() != cpu[i].size()) continue;
    bool same = true;
    for (size_t r = 0; r < gpu[i].size(); ++r) {
      const RetrievalNeighbor& g = gpu[i][r];
      const RetrievalNeighbor& c = cpu[i][r];
      EXPECT_NE(g.image, i);
      EXPECT_NEAR(g.score, ExactScore(view, i, g.image), kScoreTolerance) << "image " << i << " rank " << r;
      EXPECT_NEAR(g.score, c.score, kScoreTolerance) << "image " << i << " rank " << r;
      if (g.image != c.image) {
        same = false;
        // A swap of near-equal scores: the CPU scores the GPU's pick as high.
        EXPECT_NEAR(ExactScore(view, i, g.image), c.score, kScoreTolerance) << "image " << i << " rank " << r;
      }
      if (r > 0) {
        const RetrievalNeighbor& before = gpu[i][r - 1];
        EXPECT_TRUE(before.score > g.score || (before.score == g.score && before.image < g.image))
            << "image " << i << " rank " << r;
      }
    }
    identical += same;
  }
  return gpu.empty() ? 1.0 : static_cast<double>(identical) / static_cast<double>(gpu.size());
}

// The same images in the same order (the scores aside).
bool SameImages(const Lists& a, const Lists& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].size() != b[i].size()) return false;
    for (size_t r = 0; r < a[i].size(); ++r) {
      if (a[i][r].image != b[i][r].image) return false;
    }
  }
  return true;
}

// The same images and scores in the same order.
bool SameLists(const Lists& a, const Lists& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].size() != b[i].size()) return false;
    for (size_t r = 0; r < a[i].size(); ++r) {
      if (a[i][r].image != b[i][r].image || a[i][r].score != b[i][r].score) return false;
    }
  }
  return true;
}

class GpuRetrieval : public ::testing::Test {
 protected:
  void SetUp() override {
    SKIP_WITHOUT_CUDA_DEVICE();
    resources_ = std::make_unique<cuda::GpuResources>(0, 0);
    config_.resources = resources_.get();
  }
  std::unique_ptr<cuda::GpuResources> resources_;
  cuda::GpuRetrievalConfig config_;
};

TEST_F(GpuRetrieval, RandomWordsMatchTheCpu) {
  const ImageRetrievalIndex index(RandomImages(400, 600, 1u << 15, 1), 1u << 15, 2);
  for (size_t k : {size_t{1}, size_t{10}, size_t{50}}) {
    const Lists gpu = cuda::GpuAllTopK(index.View(), k, config_);
    EXPECT_GE(CompareWithCpu(index.View(), gpu, index.AllTopK(k), k), 0.99) << "k " << k;
  }
}

TEST_F(GpuRetrieval, StreetMatchesTheCpuAndFindsItsNeighbours) {
  uint32_t vocabulary = 0;
  std::vector<ImageWords> street = StreetImages(600, 1024, 4, 20, 2, &vocabulary);
  const ImageRetrievalIndex index(std::move(street), vocabulary, 2, 0.05);
  const size_t k = 20;
  const Lists gpu = cuda::GpuAllTopK(index.View(), k, config_);
  EXPECT_GE(CompareWithCpu(index.View(), gpu, index.AllTopK(k), k), 0.99);
  // The street's own neighbours (within 9 units) come first.
  size_t near = 0, total = 0;
  for (size_t i = 0; i < gpu.size(); ++i) {
    for (size_t r = 0; r < gpu[i].size() && r < 10; ++r) {
      near += std::abs(static_cast<long>(gpu[i][r].image) - static_cast<long>(i)) <= 9;
      ++total;
    }
  }
  EXPECT_GT(static_cast<double>(near) / static_cast<double>(total), 0.9);
}

TEST_F(GpuRetrieval, SameNeighboursOnEveryRun) {
  uint32_t vocabulary = 0;
  std::vector<ImageWords> street = StreetImages(500, 512, 4, 19, 3, &vocabulary);
  const ImageRetrievalIndex index(std::move(street), vocabulary, 2, 0.05);
  const Lists first = cuda::GpuAllTopK(index.View(), 30, config_);
  const Lists second = cuda::GpuAllTopK(index.View(), 30, config_);
  EXPECT_TRUE(SameLists(first, second));
}

TEST_F(GpuRetrieval, TilesGiveTheSameNeighbours) {
  uint32_t vocabulary = 0;
  std::vector<ImageWords> street = StreetImages(700, 512, 4, 19, 4, &vocabulary);
  const ImageRetrievalIndex index(std::move(street), vocabulary, 2, 0.05);
  cuda::GpuRetrievalStats whole_stats, tiled_stats;
  const Lists whole = cuda::GpuAllTopK(index.View(), 25, config_, &whole_stats);
  cuda::GpuRetrievalConfig tiled = config_;
  tiled.max_images_per_tile = 96;  // 8 tiles, the last one shorter
  const Lists cut = cuda::GpuAllTopK(index.View(), 25, tiled, &tiled_stats);
  EXPECT_EQ(whole_stats.tiles, 1u);
  EXPECT_EQ(tiled_stats.tiles, 8u);
  EXPECT_TRUE(SameLists(whole, cut));
  EXPECT_GE(CompareWithCpu(index.View(), cut, index.AllTopK(25), 25), 0.99);
}

TEST_F(GpuRetrieval, ImagesPastOneBlocksSharedMemoryAreTiled) {
  // 70,000 images: more 32-bit scores than one block's shared memory holds
  // (about 57,800 on an H100 or H200), so the device's own limit tiles them.
  const ImageRetrievalIndex index(RandomImages(70000, 20, 1u << 16, 8), 1u << 16, -1);
  cuda::GpuRetrievalStats stats;
  const Lists gpu = cuda::GpuAllTopK(index.View(), 5, config_, &stats);
  EXPECT_GE(stats.tiles, 2u);
  EXPECT_GE(CompareWithCpu(index.View(), gpu, index.AllTopK(5), 5), 0.99);
}

TEST_F(GpuRetrieval, KPastTheImagesReturnsEveryImageSharingAWord) {
  const ImageRetrievalIndex index(RandomImages(60, 300, 4000, 5), 4000, 2);
  const size_t k = 100;  // more than the 59 other images
  const Lists gpu = cuda::GpuAllTopK(index.View(), k, config_);
  const Lists cpu = index.AllTopK(k);
  EXPECT_GE(CompareWithCpu(index.View(), gpu, cpu, k), 0.99);
  for (const auto& list : gpu) EXPECT_EQ(list.size(), 59u);  // 300 words of 4,000: every pair shares some
}

TEST_F(GpuRetrieval, ImagesSharingNoWordAreNeverNeighbours) {
  // Images 0 .. 9 overlap their neighbours; 10 and 11 hold words no other
  // image holds; 12 holds none at all.
  std::vector<ImageWords> images(13);
  for (uint32_t i = 0; i < 10; ++i) {
    for (uint32_t w = 10 * i; w < 10 * i + 40; ++w) images[i].indexed.push_back(w);
  }
  for (uint32_t w = 900; w < 950; ++w) images[10].indexed.push_back(w);
  for (uint32_t w = 950; w < 990; ++w) images[11].indexed.push_back(w);
  const ImageRetrievalIndex index(images, 1000, 1);
  const Lists gpu = cuda::GpuAllTopK(index.View(), 20, config_);
  const Lists cpu = index.AllTopK(20);
  EXPECT_EQ(CompareWithCpu(index.View(), gpu, cpu, 20), 1.0);
  EXPECT_TRUE(gpu[10].empty());
  EXPECT_TRUE(gpu[11].empty());
  EXPECT_TRUE(gpu[12].empty());
  for (size_t i = 0; i < 10; ++i) {
    for (const RetrievalNeighbor& n : gpu[i]) EXPECT_LT(n.image, 10u);
  }
  // Equal scores: 4 and 6 share as many words of equal weight with 5; the
  // smaller position first, as on the CPU.
  ASSERT_GE(gpu[5].size(), 2u);
  EXPECT_EQ(gpu[5][0].image, 4u);
  EXPECT_EQ(gpu[5][1].image, 6u);
  EXPECT_EQ(gpu[5][0].score, gpu[5][1].score);
}

TEST_F(GpuRetrieval, AmongEqualScoresTheLowestPositionsAreKept) {
  // 699 images of the same 30 words (the last image holds others, so the
  // words keep an idf above 0): every score ties, and the k kept are the k
  // lowest positions but the query's own, in one tile and over two.
  std::vector<ImageWords> images(700);
  for (size_t i = 0; i + 1 < images.size(); ++i) {
    for (uint32_t w = 0; w < 30; ++w) images[i].indexed.push_back(w);
  }
  for (uint32_t w = 50; w < 60; ++w) images.back().indexed.push_back(w);
  const ImageRetrievalIndex index(images, 100, 1);
  cuda::GpuRetrievalConfig tiled = config_;
  tiled.max_images_per_tile = 400;
  const std::vector<uint32_t> queries = {2, 600};
  const Lists cpu = index.TopKOf(queries, 4);
  ASSERT_EQ(cpu[0].size(), 4u);
  EXPECT_EQ(cpu[0][2].image, 3u);  // 0, 1, 3, 4
  for (const cuda::GpuRetrievalConfig& config : {config_, tiled}) {
    const Lists gpu = cuda::GpuTopK(index.View(), queries, 4, config);
    EXPECT_TRUE(SameImages(gpu, cpu));
    EXPECT_TRUE(gpu[1].size() == 4 && gpu[1][0].image == 0u && gpu[1][3].image == 3u);
  }
}

TEST_F(GpuRetrieval, QueriesOfSomeImagesEqualTheirRowsOfAll) {
  uint32_t vocabulary = 0;
  std::vector<ImageWords> street = StreetImages(300, 512, 4, 19, 6, &vocabulary);
  const ImageRetrievalIndex index(std::move(street), vocabulary, 2, 0.05);
  const Lists all = cuda::GpuAllTopK(index.View(), 15, config_);
  const std::vector<uint32_t> some = {299, 0, 150, 7, 150};
  const Lists asked = cuda::GpuTopK(index.View(), some, 15, config_);
  ASSERT_EQ(asked.size(), some.size());
  for (size_t q = 0; q < some.size(); ++q) EXPECT_TRUE(SameLists({asked[q]}, {all[some[q]]})) << "query " << q;
  EXPECT_THROW(cuda::GpuTopK(index.View(), {300}, 15, config_), std::out_of_range);
  EXPECT_TRUE(cuda::GpuTopK(index.View(), some, 0, config_)[0].empty());
}

TEST_F(GpuRetrieval, ABudgetWithoutRoomForThePostingsThrowsDeviceMemoryError) {
  uint32_t vocabulary = 0;
  std::vector<ImageWords> street = StreetImages(200, 1024, 4, 20, 7, &vocabulary);
  const ImageRetrievalIndex index(std::move(street), vocabulary, 2, 0.05);
  ASSERT_GT(cuda::GpuRetrievalResidentBytes(index.View()), size_t{4} << 20);
  cuda::GpuResources small(0, size_t{4} << 20);
  cuda::GpuRetrievalConfig config;
  config.resources = &small;
  EXPECT_THROW(cuda::GpuAllTopK(index.View(), 10, config), DeviceMemoryError);
}

}  // namespace
}  // namespace cashash
