#include "cashash/retrieval/image_retrieval_index.h"

#include <gtest/gtest.h>

#include <random>
#include <stdexcept>

#include "cashash/matching/mean_descriptor.h"
#include "cashash/retrieval/visual_words.h"
#include "synthetic_sift.h"

namespace cashash {
namespace {

using testing_support::RandomSift;

// Words of an image drawn from `first` .. `first + count` of a vocabulary.
ImageWords WordRange(uint32_t first, uint32_t count) {
  ImageWords words;
  for (uint32_t w = first; w < first + count; ++w) words.indexed.push_back(w);
  words.query = words.indexed;
  return words;
}

TEST(ImageRetrievalIndex, IdenticalImagesRankFirst) {
  // 0 and 3 hold the same words, 1 and 2 overlap 0 partly, 4 not at all.
  const std::vector<ImageWords> images = {WordRange(0, 100), WordRange(50, 100), WordRange(80, 100), WordRange(0, 100),
                                          WordRange(500, 100)};
  const ImageRetrievalIndex index(images, 1000, 1);
  const std::vector<RetrievalNeighbor> top = index.TopK(0, 10);
  ASSERT_EQ(top.size(), 3u);  // image 4 shares no word, image 0 itself is left out
  EXPECT_EQ(top[0].image, 3u);
  EXPECT_NEAR(top[0].score, 1.0f, 1e-5f);
  EXPECT_EQ(top[1].image, 1u);  // 50 shared words before 20
  EXPECT_EQ(top[2].image, 2u);
  EXPECT_GT(top[1].score, top[2].score);
  EXPECT_TRUE(index.TopK(4, 10).empty());
}

TEST(ImageRetrievalIndex, TopKSizesAndOrder) {
  std::vector<ImageWords> images;
  for (uint32_t i = 0; i < 20; ++i) images.push_back(WordRange(10 * i, 60));  // each overlaps its 5 neighbours each side
  const ImageRetrievalIndex index(images, 1000, 2);
  for (size_t k : {size_t{1}, size_t{3}, size_t{5}, size_t{50}}) {
    const std::vector<RetrievalNeighbor> top = index.TopK(10, k);
    EXPECT_EQ(top.size(), std::min<size_t>(k, 10));
    for (size_t r = 1; r < top.size(); ++r) EXPECT_GE(top[r - 1].score, top[r].score);
    for (const RetrievalNeighbor& n : top) EXPECT_NE(n.image, 10u);
  }
  // The nearest in the sequence first: 9 and 11 tie (same score), the smaller position first.
  const std::vector<RetrievalNeighbor> top = index.TopK(10, 2);
  EXPECT_EQ(top[0].image, 9u);
  EXPECT_EQ(top[1].image, 11u);
}

TEST(ImageRetrievalIndex, RareWordsWeighMoreThanCommonOnes) {
  // Image 0 shares 10 words with 1 that every image holds, and 5 with 2
  // that only 0 and 2 hold: the rare ones decide.
  std::vector<ImageWords> images(6);
  for (ImageWords& image : images) {
    for (uint32_t w = 0; w < 10; ++w) image.indexed.push_back(w);
  }
  for (uint32_t w = 100; w < 105; ++w) {
    images[0].indexed.push_back(w);
    images[2].indexed.push_back(w);
  }
  for (size_t i = 0; i < images.size(); ++i) {
    for (uint32_t w = 0; w < 20; ++w) images[i].indexed.push_back(static_cast<uint32_t>(200 + 20 * i + w));
    images[i].query = images[i].indexed;
  }
  const ImageRetrievalIndex index(images, 1000, 1);
  const std::vector<RetrievalNeighbor> top = index.TopK(0, 1);
  ASSERT_EQ(top.size(), 1u);
  EXPECT_EQ(top[0].image, 2u);
}

TEST(ImageRetrievalIndex, StopWordsAreLeftOut) {
  // Images 0..69 of 120 hold words 0..9; pairs (2k, 2k + 1) share 20
  // words of their own. Held by more than 50 images (max(0.05 x 120, 50)),
  // words 0..9 are stop words.
  std::vector<ImageWords> images(120);
  for (size_t i = 0; i < images.size(); ++i) {
    for (uint32_t w = 0; w < 10 && i < 70; ++w) images[i].indexed.push_back(w);
    for (uint32_t w = 0; w < 20; ++w) images[i].indexed.push_back(static_cast<uint32_t>(100 + 20 * (i / 2) + w));
  }
  const ImageRetrievalIndex all(images, 5000, 2, 1.0);
  const ImageRetrievalIndex stopped(images, 5000, 2, 0.05);
  EXPECT_EQ(all.PostingsReadByAllQueries(), 70u * (10 * 70) + 120u * 20 * 2);
  EXPECT_EQ(stopped.PostingsReadByAllQueries(), 120u * 20 * 2);
  for (size_t i = 0; i < images.size(); ++i) {
    const std::vector<RetrievalNeighbor> top = stopped.TopK(i, 5);
    ASSERT_EQ(top.size(), 1u);
    EXPECT_EQ(top[0].image, i ^ 1u);
    EXPECT_NEAR(top[0].score, 1.0f, 1e-5f);
    EXPECT_EQ(all.TopK(i, 1)[0].image, i ^ 1u);
  }
}

TEST(ImageRetrievalIndex, SameResultOnAnyThreadCount) {
  std::mt19937 rng(5);
  std::uniform_int_distribution<uint32_t> word(0, 4999);
  std::vector<ImageWords> images(40);
  for (ImageWords& image : images) {
    for (int f = 0; f < 300; ++f) image.indexed.push_back(word(rng));
    image.query = image.indexed;
    for (int f = 0; f < 300; ++f) image.query.push_back(word(rng));
  }
  const auto one = ImageRetrievalIndex(images, 5000, 1).AllTopK(7);
  const auto four = ImageRetrievalIndex(images, 5000, 4).AllTopK(7);
  ASSERT_EQ(one.size(), four.size());
  for (size_t i = 0; i < one.size(); ++i) {
    ASSERT_EQ(one[i].size(), 7u);
    ASSERT_EQ(one[i].size(), four[i].size());
    for (size_t r = 0; r < one[i].size(); ++r) {
      EXPECT_EQ(one[i][r].image, four[i][r].image);
      EXPECT_EQ(one[i][r].score, four[i][r].score);
    }
  }
}

TEST(ImageRetrievalIndex, TopKOfSomeImagesAndTheViewOfTheArrays) {
  std::vector<ImageWords> images;
  for (uint32_t i = 0; i < 20; ++i) images.push_back(WordRange(10 * i, 60));
  const ImageRetrievalIndex index(images, 1000, 3);
  const std::vector<uint32_t> asked = {19, 3, 3, 0};
  const auto lists = index.TopKOf(asked, 4);
  ASSERT_EQ(lists.size(), asked.size());
  for (size_t q = 0; q < asked.size(); ++q) {
    const auto alone = index.TopK(asked[q], 4);
    ASSERT_EQ(lists[q].size(), alone.size());
    for (size_t r = 0; r < alone.size(); ++r) {
      EXPECT_EQ(lists[q][r].image, alone[r].image);
      EXPECT_EQ(lists[q][r].score, alone[r].score);
      if (r > 0) {
        EXPECT_TRUE(RanksBefore(lists[q][r - 1], lists[q][r]));
      }
    }
  }
  EXPECT_THROW(index.TopKOf({20}, 1), std::out_of_range);

  // The view: every query word has postings, by image ascending, and the
  // dot product over them is the score TopK gives.
  const RetrievalIndexView view = index.View();
  EXPECT_EQ(view.num_images, 20u);
  EXPECT_EQ(view.vocabulary_size, 1000u);
  const RetrievalNeighbor best = index.TopK(3, 1)[0];
  double score = 0;
  for (size_t w = view.query_offsets[3]; w < view.query_offsets[4]; ++w) {
    const RetrievalQueryWord word = view.queries[w];
    ASSERT_LT(view.posting_offsets[word.word], view.posting_offsets[word.word + 1]);
    for (size_t p = view.posting_offsets[word.word]; p < view.posting_offsets[word.word + 1]; ++p) {
      if (p > view.posting_offsets[word.word]) {
        EXPECT_LT(view.postings[p - 1].image, view.postings[p].image);
      }
      if (view.postings[p].image == best.image) score += static_cast<double>(word.weight) * view.postings[p].weight;
    }
  }
  EXPECT_NEAR(score, best.score, 1e-6);
}

TEST(ImageRetrievalIndex, RefusesWordsPastTheVocabulary) {
  EXPECT_THROW(ImageRetrievalIndex({WordRange(0, 10), WordRange(95, 10)}, 100, 1), std::invalid_argument);
  const ImageRetrievalIndex index({WordRange(0, 10), WordRange(5, 10)}, 100, 1);
  EXPECT_THROW(index.TopK(2, 1), std::out_of_range);
}

TEST(UnionOfNeighborPairs, EachPairOnceSmallerFirst) {
  const std::vector<std::vector<RetrievalNeighbor>> neighbors = {
      {{2, 0.9f}, {1, 0.5f}}, {{0, 0.5f}}, {{0, 0.9f}, {3, 0.1f}}, {}};
  const std::vector<std::pair<uint32_t, uint32_t>> expected = {{0, 1}, {0, 2}, {2, 3}};
  EXPECT_EQ(UnionOfNeighborPairs(neighbors), expected);
}

TEST(NearestCellFlips, LeastCertainBitsFirst) {
  const float margins[6] = {5.f, 0.5f, 3.f, 0.6f, 9.f, 0.7f};
  // Singles of bits 1, 3, 5 (0.25, 0.36, 0.49), then bits 1 and 3 together (0.61).
  const std::vector<uint32_t> expected = {1u << 1, 1u << 3, 1u << 5, (1u << 1) | (1u << 3)};
  EXPECT_EQ(NearestCellFlips(margins, 6, 5), expected);
  EXPECT_TRUE(NearestCellFlips(margins, 6, 1).empty());
}

// Descriptors: image b holds noisy copies of image a's, image c others.
FeatureDescriptors RandomImage(std::mt19937* rng, int n) {
  FeatureDescriptors d;
  for (int i = 0; i < n; ++i) {
    const std::vector<uint8_t> row = RandomSift(rng);
    d.data.insert(d.data.end(), row.begin(), row.end());
  }
  return d;
}

FeatureDescriptors NoisyCopy(const FeatureDescriptors& in, std::mt19937* rng, int noise) {
  FeatureDescriptors out = in;
  std::uniform_int_distribution<int> delta(-noise, noise);
  for (uint8_t& v : out.data) v = static_cast<uint8_t>(std::clamp(int{v} + delta(*rng), 0, 255));
  return out;
}

TEST(VisualWordHasher, WordsOfTheSameDescriptorsAreTheSame) {
  std::mt19937 rng(3);
  const FeatureDescriptors a = RandomImage(&rng, 200);
  const MeanDescriptor mean = ComputeMeanDescriptor({&a});
  RetrievalOptions options;
  options.num_tables = 3;
  options.num_nearest_neighbors = 4;
  const VisualWordHasher hasher(options, 12, mean);
  const ImageWords words = hasher.Words(a);
  EXPECT_EQ(words.indexed.size(), 200u * 3);
  EXPECT_EQ(words.query.size(), 200u * 3 * 4);
  for (size_t i = 0; i < 200 * 3; ++i) {
    EXPECT_EQ(words.query[4 * i], words.indexed[i]);  // own cell first
    EXPECT_LT(words.indexed[i], hasher.vocabulary_size());
    EXPECT_EQ(words.indexed[i] >> 12, i % 3);  // table in the high bits
  }
  EXPECT_EQ(hasher.Words(a).indexed, words.indexed);
  // Rows select features.
  const ImageWords some = hasher.Words(a, {5, 7});
  ASSERT_EQ(some.indexed.size(), 6u);
  EXPECT_EQ(some.indexed[0], words.indexed[15]);
  EXPECT_EQ(some.indexed[3], words.indexed[21]);
  EXPECT_THROW(hasher.Words(a, {200}), std::invalid_argument);
}

TEST(VisualWordHasher, NoisyCopiesAreRetrievedBeforeUnrelatedImages) {
  std::mt19937 rng(8);
  std::vector<FeatureDescriptors> scenes;
  for (int s = 0; s < 6; ++s) scenes.push_back(RandomImage(&rng, 300));
  // Images 2s and 2s + 1 are two noisy views of scene s.
  std::vector<FeatureDescriptors> images;
  for (const FeatureDescriptors& scene : scenes) {
    images.push_back(NoisyCopy(scene, &rng, 6));
    images.push_back(NoisyCopy(scene, &rng, 6));
  }
  std::vector<const FeatureDescriptors*> pointers;
  for (const FeatureDescriptors& image : images) pointers.push_back(&image);
  RetrievalOptions options;
  const VisualWordHasher hasher(options, RetrievalBitsPerWord(options, 300), ComputeMeanDescriptor(pointers));
  std::vector<ImageWords> words;
  for (const FeatureDescriptors& image : images) words.push_back(hasher.Words(image));
  const ImageRetrievalIndex index(words, hasher.vocabulary_size(), 2);
  const auto top = index.AllTopK(1);
  for (size_t i = 0; i < images.size(); ++i) {
    ASSERT_EQ(top[i].size(), 1u) << "image " << i;
    EXPECT_EQ(top[i][0].image, i ^ 1u) << "image " << i;
  }
}

TEST(RetrievalOptions, CheckNamesTheOption) {
  RetrievalOptions options;
  EXPECT_EQ(options.Check(), "");
  options.num_images = 0;
  EXPECT_NE(options.Check().find("VocabTreeMatching.num_images"), std::string::npos);
  options = RetrievalOptions();
  options.bits_per_word = 30;
  EXPECT_NE(options.Check().find("Retrieval.bits_per_word"), std::string::npos);
  options = RetrievalOptions();
  options.max_num_features = 0;
  EXPECT_NE(options.Check().find("max_num_features"), std::string::npos);
  EXPECT_EQ(RetrievalBitsPerWord(RetrievalOptions(), 4096), 22);
  EXPECT_EQ(RetrievalBitsPerWord(RetrievalOptions(), 10), 13);
  EXPECT_EQ(RetrievalBitsPerWord(RetrievalOptions(), 1 << 20), RetrievalOptions::kMaxBitsPerWord);
}

}  // namespace
}  // namespace cashash
