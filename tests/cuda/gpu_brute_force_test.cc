// The GPU brute-force kernels against a naive CPU reference: exact equality
// of best / second best dots and best indices, and of the final matches
// (ratio test, max_distance, cross-check), on random SIFT-like descriptors
// with planted near-duplicates, exact duplicates (ties), zero rows and
// saturated rows. Skips when no CUDA device is present.
#include <cuda_runtime.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "cashash/matching/brute_force_matcher.h"
#include "cashash/matching/descriptor_distance.h"
#include "cashash_cuda/matching/brute_force_matcher.cuh"

namespace cashash {
namespace {

using cuda::BestTwoProblem;
using cuda::BruteForceKernels;
using cuda::DeviceDescriptors;
using cuda::MatchThresholds;

#define ASSERT_CUDA(call) ASSERT_EQ((call), cudaSuccess) << #call

bool HaveDevice(std::string* why) {
  int count = 0;
  const cudaError_t error = cudaGetDeviceCount(&count);
  if (error != cudaSuccess) {
    *why = cudaGetErrorString(error);
    return false;
  }
  if (count == 0) {
    *why = "0 devices";
    return false;
  }
  return true;
}

// One SIFT-like descriptor: |gaussian| components normalised to 512 and
// capped at 255, as COLMAP stores them.
std::vector<uint8_t> RandomDescriptor(std::mt19937& rng) {
  std::normal_distribution<float> normal(0.f, 1.f);
  std::vector<float> v(kDescriptorDim);
  float norm = 0.f;
  for (float& x : v) {
    x = std::fabs(normal(rng));
    x = x * x;  // peakier histograms, like real SIFT
    norm += x * x;
  }
  norm = std::sqrt(norm);
  std::vector<uint8_t> out(kDescriptorDim);
  for (int d = 0; d < kDescriptorDim; ++d) {
    out[d] = static_cast<uint8_t>(std::min(255.f, std::round(512.f * v[d] / norm)));
  }
  return out;
}

struct Image {
  std::vector<uint8_t> data;
  int rows() const { return static_cast<int>(data.size() / kDescriptorDim); }
  const uint8_t* row(int i) const { return data.data() + static_cast<size_t>(i) * kDescriptorDim; }
};

Image RandomImage(int rows, std::mt19937& rng) {
  Image image;
  for (int i = 0; i < rows; ++i) {
    const std::vector<uint8_t> d = RandomDescriptor(rng);
    image.data.insert(image.data.end(), d.begin(), d.end());
  }
  return image;
}

// Second image: a fraction of rows are noisy copies of rows of `source`
// (true matches), some exact copies (ties), the rest random.
Image PlantedImage(const Image& source, int rows, std::mt19937& rng) {
  Image image = RandomImage(rows, rng);
  if (source.rows() == 0) return image;
  std::uniform_int_distribution<int> pick(0, source.rows() - 1);
  std::uniform_int_distribution<int> noise(-6, 6);
  std::uniform_int_distribution<int> kind(0, 9);
  for (int i = 0; i < rows; ++i) {
    const int k = kind(rng);
    if (k >= 6) continue;  // stays random
    const uint8_t* src = source.row(pick(rng));
    uint8_t* dst = image.data.data() + static_cast<size_t>(i) * kDescriptorDim;
    for (int d = 0; d < kDescriptorDim; ++d) {
      const int v = k == 0 ? src[d] : std::clamp(int{src[d]} + noise(rng), 0, 255);
      dst[d] = static_cast<uint8_t>(v);
    }
  }
  return image;
}

struct Reference {
  std::vector<int> best_dot, second_dot, best_idx;
};

// COLMAP's loop, row by row; rows split over threads.
Reference NaiveBestTwo(const Image& a, const Image& b) {
  Reference r;
  const int n = a.rows();
  r.best_dot.assign(n, 0);
  r.second_dot.assign(n, 0);
  r.best_idx.assign(n, -1);
  const int workers = std::max(1u, std::thread::hardware_concurrency());
  std::vector<std::thread> threads;
  for (int w = 0; w < workers; ++w) {
    threads.emplace_back([&, w] {
      for (int i = w; i < n; i += workers) {
        int best = 0, second = 0, index = -1;
        for (int j = 0; j < b.rows(); ++j) {
          int dot = 0;
          for (int d = 0; d < kDescriptorDim; ++d) dot += int{a.row(i)[d]} * int{b.row(j)[d]};
          if (dot > best) {
            second = best;
            best = dot;
            index = j;
          } else if (dot > second) {
            second = dot;
          }
        }
        r.best_dot[i] = best;
        r.second_dot[i] = second;
        r.best_idx[i] = index;
      }
    });
  }
  for (auto& t : threads) t.join();
  return r;
}

FeatureMatches ReferenceMatches(const Reference& r12, const Reference& r21, const MatchThresholds& t) {
  auto accepted = [&](const Reference& r, int i) {
    return r.best_idx[i] >= 0 && AcceptSiftMatch(r.best_dot[i], r.second_dot[i], t.max_ratio, t.max_distance);
  };
  FeatureMatches matches;
  for (int i = 0; i < static_cast<int>(r12.best_idx.size()); ++i) {
    if (!accepted(r12, i)) continue;
    const int j = r12.best_idx[i];
    if (t.cross_check && (!accepted(r21, j) || r21.best_idx[j] != i)) continue;
    matches.push_back({static_cast<point2D_t>(i), static_cast<point2D_t>(j)});
  }
  return matches;
}

// Device copy of an image, freed on destruction.
class DeviceImage {
 public:
  explicit DeviceImage(const Image& image) : rows_(image.rows()) {
    if (!image.data.empty()) {
      EXPECT_EQ(cudaMalloc(&ptr_, image.data.size()), cudaSuccess);
      EXPECT_EQ(cudaMemcpy(ptr_, image.data.data(), image.data.size(), cudaMemcpyHostToDevice), cudaSuccess);
    }
  }
  ~DeviceImage() {
    if (ptr_ != nullptr) cudaFree(ptr_);
  }
  DeviceImage(const DeviceImage&) = delete;
  DeviceImage& operator=(const DeviceImage&) = delete;
  DeviceDescriptors view() const { return {static_cast<const uint8_t*>(ptr_), rows_}; }

 private:
  void* ptr_ = nullptr;
  int rows_ = 0;
};

class GpuBruteForceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string why;
    if (!HaveDevice(&why)) GTEST_SKIP() << "no CUDA device: " << why;
  }
};

struct Case {
  int n1, n2;
};

// Sizes of the brief: empty, single, tiny, not a multiple of any tile, and a
// very unbalanced pair.
const std::vector<Case> kCases = {{0, 0}, {0, 5}, {5, 0}, {1, 1}, {7, 7}, {1, 300},
                                  {1000, 1000}, {5000, 5000}, {40000, 1000}};

// Runs every search of `images` pairs (both directions) in one launch and
// compares each with the naive reference. One test because the single
// launch over every case is what it checks.
TEST_F(GpuBruteForceTest, BestTwoEqualsNaiveReferenceInOneBatch) {
  std::mt19937 rng(1234);
  std::vector<Image> first, second;
  for (const Case& c : kCases) {
    first.push_back(RandomImage(c.n1, rng));
    second.push_back(PlantedImage(first.back(), c.n2, rng));
  }
  // Edge rows: zero descriptors (dot 0 everywhere -> index -1), saturated
  // rows (largest possible dots), and duplicates inside b (ties).
  {
    Image& a = first[6];
    Image& b = second[6];
    std::fill(a.data.begin(), a.data.begin() + kDescriptorDim, 0);            // a row 0 zero
    std::fill(a.data.begin() + kDescriptorDim, a.data.begin() + 2 * kDescriptorDim, 255);  // a row 1 saturated
    std::fill(b.data.begin() + 5 * kDescriptorDim, b.data.begin() + 6 * kDescriptorDim, 255);  // b row 5
    std::fill(b.data.begin() + 700 * kDescriptorDim, b.data.begin() + 701 * kDescriptorDim, 255);  // tie
    std::copy(b.row(10), b.row(11), b.data.begin() + 999 * kDescriptorDim);  // tie across tiles
  }

  std::vector<std::unique_ptr<DeviceImage>> d1, d2;
  std::vector<BestTwoProblem> problems;
  std::vector<std::pair<int, bool>> which;  // case, reversed
  std::vector<int*> outputs;
  for (size_t k = 0; k < kCases.size(); ++k) {
    d1.push_back(std::make_unique<DeviceImage>(first[k]));
    d2.push_back(std::make_unique<DeviceImage>(second[k]));
    for (bool reversed : {false, true}) {
      BestTwoProblem p;
      const DeviceDescriptors a = reversed ? d2[k]->view() : d1[k]->view();
      const DeviceDescriptors b = reversed ? d1[k]->view() : d2[k]->view();
      p.a = a.data;
      p.n_a = a.rows;
      p.b = b.data;
      p.n_b = b.rows;
      int* out = nullptr;
      ASSERT_CUDA(cudaMalloc(&out, std::max(1, 3 * p.n_a) * sizeof(int)));
      ASSERT_CUDA(cudaMemset(out, 0xAB, std::max(1, 3 * p.n_a) * sizeof(int)));  // poison
      outputs.push_back(out);
      p.best_dot = out;
      p.second_dot = out + p.n_a;
      p.best_idx = out + 2 * p.n_a;
      problems.push_back(p);
      which.emplace_back(static_cast<int>(k), reversed);
    }
  }
  cuda::GpuResources resources(0, 0);
  BruteForceKernels kernels(nullptr, &resources);
  kernels.EnqueueBestTwo(problems);
  ASSERT_CUDA(cudaStreamSynchronize(kernels.stream()));

  for (size_t q = 0; q < problems.size(); ++q) {
    const int k = which[q].first;
    const bool reversed = which[q].second;
    const Image& a = reversed ? second[k] : first[k];
    const Image& b = reversed ? first[k] : second[k];
    SCOPED_TRACE("case " + std::to_string(a.rows()) + " x " + std::to_string(b.rows()));
    const Reference ref = NaiveBestTwo(a, b);
    const int n = a.rows();
    std::vector<int> got(3 * static_cast<size_t>(n));
    if (n > 0) {
      ASSERT_CUDA(cudaMemcpy(got.data(), outputs[q], got.size() * sizeof(int), cudaMemcpyDeviceToHost));
    }
    int mismatches = 0;
    for (int i = 0; i < n && mismatches < 5; ++i) {
      const bool same = got[i] == ref.best_dot[i] && got[n + i] == ref.second_dot[i] &&
                        got[2 * n + i] == ref.best_idx[i];
      if (!same) {
        ++mismatches;
        ADD_FAILURE() << "row " << i << ": gpu (" << got[i] << ", " << got[n + i] << ", " << got[2 * n + i]
                      << ") reference (" << ref.best_dot[i] << ", " << ref.second_dot[i] << ", "
                      << ref.best_idx[i] << ")";
      }
    }
    EXPECT_EQ(mismatches, 0);
  }
  // The planted edge rows really exercised what they were meant to.
  {
    const Reference ref = NaiveBestTwo(first[6], second[6]);
    EXPECT_EQ(ref.best_idx[0], -1);
    EXPECT_EQ(ref.best_dot[1], 128 * 255 * 255);
    EXPECT_EQ(ref.best_idx[1], 5);
    EXPECT_EQ(ref.second_dot[1], 128 * 255 * 255);
  }
  for (int* out : outputs) cudaFree(out);
}

// The kernel skips an 8-column strip when no dot in it beats its row's
// second best so far. Orders that make it skip almost everything, or
// nothing, and ties the skip must not break: b is 3,000 random rows and
// then the same rows again (every best has an equal later copy, which must
// not take the index, and the second equals the best), 8 late noisy copies
// of rows of a (a late best after thousands of skipped strips), and b
// sorted by the dot with a's row 0, descending and ascending; a has a zero
// row and a row that is b's first row. Every row must be the reference's.
TEST_F(GpuBruteForceTest, SkippedStripsKeepTheReferenceBestTwo) {
  std::mt19937 rng(77);
  Image a = RandomImage(300, rng);
  std::fill(a.data.begin() + 5 * kDescriptorDim, a.data.begin() + 6 * kDescriptorDim, 0);  // zero row
  Image twice = RandomImage(3000, rng);
  std::copy(twice.row(0), twice.row(1), a.data.begin() + 7 * kDescriptorDim);  // a row 7 = b row 0
  twice.data.insert(twice.data.end(), twice.data.begin(), twice.data.end());
  std::uniform_int_distribution<int> noise(-3, 3);
  for (int i = 0; i < 8; ++i) {
    std::vector<uint8_t> copy(a.row(10 + i), a.row(11 + i));
    for (uint8_t& v : copy) v = static_cast<uint8_t>(std::clamp(int{v} + noise(rng), 0, 255));
    twice.data.insert(twice.data.end(), copy.begin(), copy.end());
  }
  auto sorted_by_row0 = [&](bool descending) {
    Image b = RandomImage(5000, rng);
    std::vector<std::pair<int, int>> order;
    for (int j = 0; j < b.rows(); ++j) {
      int dot = 0;
      for (int d = 0; d < kDescriptorDim; ++d) dot += int{a.row(0)[d]} * int{b.row(j)[d]};
      order.emplace_back(descending ? -dot : dot, j);
    }
    std::sort(order.begin(), order.end());
    Image out;
    for (const auto& o : order) out.data.insert(out.data.end(), b.row(o.second), b.row(o.second + 1));
    return out;
  };
  const std::vector<Image> bs = {twice, sorted_by_row0(true), sorted_by_row0(false)};

  DeviceImage da(a);
  std::vector<std::unique_ptr<DeviceImage>> db;
  std::vector<BestTwoProblem> problems;
  std::vector<int*> outputs;
  for (const Image& b : bs) {
    db.push_back(std::make_unique<DeviceImage>(b));
    BestTwoProblem p;
    p.a = da.view().data;
    p.n_a = a.rows();
    p.b = db.back()->view().data;
    p.n_b = b.rows();
    int* out = nullptr;
    ASSERT_CUDA(cudaMalloc(&out, 3 * p.n_a * sizeof(int)));
    ASSERT_CUDA(cudaMemset(out, 0xAB, 3 * p.n_a * sizeof(int)));  // poison
    outputs.push_back(out);
    p.best_dot = out;
    p.second_dot = out + p.n_a;
    p.best_idx = out + 2 * p.n_a;
    problems.push_back(p);
  }
  cuda::GpuResources resources(0, 0);
  BruteForceKernels kernels(nullptr, &resources);
  kernels.EnqueueBestTwo(problems);
  ASSERT_CUDA(cudaStreamSynchronize(kernels.stream()));
  const int n = a.rows();
  for (size_t q = 0; q < bs.size(); ++q) {
    SCOPED_TRACE("b " + std::to_string(q));
    const Reference ref = NaiveBestTwo(a, bs[q]);
    std::vector<int> got(3 * static_cast<size_t>(n));
    ASSERT_CUDA(cudaMemcpy(got.data(), outputs[q], got.size() * sizeof(int), cudaMemcpyDeviceToHost));
    int mismatches = 0;
    for (int i = 0; i < n; ++i) {
      const bool same = got[i] == ref.best_dot[i] && got[n + i] == ref.second_dot[i] &&
                        got[2 * n + i] == ref.best_idx[i];
      if (!same && ++mismatches <= 5) {
        ADD_FAILURE() << "row " << i << ": gpu (" << got[i] << ", " << got[n + i] << ", " << got[2 * n + i]
                      << ") reference (" << ref.best_dot[i] << ", " << ref.second_dot[i] << ", "
                      << ref.best_idx[i] << ")";
      }
    }
    EXPECT_EQ(mismatches, 0);
    if (q == 0) {  // the cases were really there
      EXPECT_EQ(ref.best_idx[5], -1);
      EXPECT_EQ(ref.best_idx[7], 0);
      EXPECT_EQ(ref.second_dot[7], ref.best_dot[7]);
      for (int i = 0; i < 8; ++i) EXPECT_EQ(ref.best_idx[10 + i], 6000 + i) << "planted row " << 10 + i;
    }
  }
  for (int* out : outputs) cudaFree(out);
}

// Final matches through MatchPairs equal the reference and the CPU matcher,
// with and without cross-check and at non-default thresholds.
TEST_F(GpuBruteForceTest, MatchPairsEqualsReferenceAndCpuMatcher) {
  std::mt19937 rng(99);
  std::vector<Image> first, second;
  for (const Case& c : kCases) {
    first.push_back(RandomImage(c.n1, rng));
    second.push_back(PlantedImage(first.back(), c.n2, rng));
  }
  std::vector<std::unique_ptr<DeviceImage>> d1, d2;
  std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>> pairs;
  for (size_t k = 0; k < kCases.size(); ++k) {
    d1.push_back(std::make_unique<DeviceImage>(first[k]));
    d2.push_back(std::make_unique<DeviceImage>(second[k]));
    pairs.emplace_back(d1.back()->view(), d2.back()->view());
  }
  std::vector<Reference> r12, r21;
  for (size_t k = 0; k < kCases.size(); ++k) {
    r12.push_back(NaiveBestTwo(first[k], second[k]));
    r21.push_back(NaiveBestTwo(second[k], first[k]));
  }
  cuda::GpuResources resources(0, 0);
  BruteForceKernels kernels(nullptr, &resources);
  const std::vector<MatchThresholds> settings = {
      {0.8f, 0.7f, true}, {0.8f, 0.7f, false}, {0.95f, 1.2f, true}, {0.6f, 0.3f, true}};
  for (const MatchThresholds& t : settings) {
    SCOPED_TRACE("ratio " + std::to_string(t.max_ratio) + " distance " + std::to_string(t.max_distance) +
                 " cross_check " + std::to_string(t.cross_check));
    const std::vector<FeatureMatches> got = kernels.MatchPairs(pairs, t);
    ASSERT_EQ(got.size(), pairs.size());
    size_t total = 0;
    for (size_t k = 0; k < pairs.size(); ++k) {
      SCOPED_TRACE("case " + std::to_string(kCases[k].n1) + " x " + std::to_string(kCases[k].n2));
      const FeatureMatches expected = ReferenceMatches(r12[k], r21[k], t);
      EXPECT_EQ(got[k], expected);
      total += expected.size();
    }
    EXPECT_GT(total, 1000u);  // the planted duplicates produce real matches
  }
  // The CPU brute-force matcher of the project gives the same matches.
  for (size_t k : {4, 6, 7}) {
    SiftMatchingOptions options;
    const FeatureMatches cpu =
        BruteForceMatchPair(WidenDescriptors(FeatureDescriptors{first[k].data}, first[k].rows()),
                            WidenDescriptors(FeatureDescriptors{second[k].data}, second[k].rows()), options);
    const FeatureMatches gpu = kernels.MatchPairs({pairs[k]}, cuda::ToMatchThresholds(options))[0];
    EXPECT_EQ(gpu, cpu) << "case " << kCases[k].n1 << " x " << kCases[k].n2;
  }
}

// The reverse search runs only over the rows of image 2 that an accepted
// forward match names. Three shapes stress that gather: nearly every row
// named (image 2 is image 1), no row named (unrelated images at max_distance
// 0, which only angle 0 passes), and many rows of image 1 naming the same
// few rows of image 2 (near copies of 3 rows), where the gathered count is
// tiny and the cross-check must still reject every row whose reverse best
// is another.
TEST_F(GpuBruteForceTest, ReverseSearchOverNamedRowsEqualsFullReference) {
  std::mt19937 rng(7);
  const Image base = RandomImage(3000, rng);
  const Image unrelated = RandomImage(2000, rng);
  Image crowd;  // 4000 rows: noisy copies of rows 0..2 of `base`
  std::uniform_int_distribution<int> noise(-3, 3);
  for (int i = 0; i < 4000; ++i) {
    const uint8_t* src = base.row(i % 3);
    for (int d = 0; d < kDescriptorDim; ++d) {
      crowd.data.push_back(static_cast<uint8_t>(std::clamp(int{src[d]} + noise(rng), 0, 255)));
    }
  }
  const std::vector<std::pair<const Image*, const Image*>> cases = {
      {&base, &base}, {&base, &unrelated}, {&crowd, &base}, {&base, &crowd}};
  std::vector<std::unique_ptr<DeviceImage>> devices;
  std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>> pairs;
  std::vector<Reference> r12, r21;
  for (const auto& c : cases) {
    devices.push_back(std::make_unique<DeviceImage>(*c.first));
    devices.push_back(std::make_unique<DeviceImage>(*c.second));
    pairs.emplace_back(devices[devices.size() - 2]->view(), devices.back()->view());
    r12.push_back(NaiveBestTwo(*c.first, *c.second));
    r21.push_back(NaiveBestTwo(*c.second, *c.first));
  }
  cuda::GpuResources resources(0, 0);
  BruteForceKernels kernels(nullptr, &resources);
  const std::vector<MatchThresholds> settings = {{0.8f, 0.7f, true}, {0.8f, 0.0f, true}, {1.0f, 2.0f, true}};
  size_t matched_identical = 0;
  for (const MatchThresholds& t : settings) {
    const std::vector<FeatureMatches> got = kernels.MatchPairs(pairs, t);
    ASSERT_EQ(got.size(), pairs.size());
    for (size_t k = 0; k < pairs.size(); ++k) {
      SCOPED_TRACE("case " + std::to_string(k) + " max_distance " + std::to_string(t.max_distance));
      const FeatureMatches expected = ReferenceMatches(r12[k], r21[k], t);
      EXPECT_EQ(got[k], expected);
      if (t.max_distance == 0.0f && k == 1) {
        EXPECT_TRUE(expected.empty());
      }
    }
    if (t.max_distance == 0.7f) {
      for (const FeatureMatch& m : got[0]) matched_identical += m.point2D_idx1 == m.point2D_idx2 ? 1 : 0;
    }
  }
  // An image against itself: nearly every row is its own mutual best (a row
  // whose dot with another also reaches angle 0 fails the ratio test).
  EXPECT_GE(matched_identical, static_cast<size_t>(base.rows()) * 99 / 100);
}

// The acceptance boundary: dots on either side of the max_distance and
// ratio thresholds decide exactly as AcceptSiftMatch on the CPU. Built from
// descriptors with 4 equal non-zero dimensions, so that every dot is chosen
// by hand: query 255 in dimensions 0..3, candidate c there, dot 1020 c.
TEST_F(GpuBruteForceTest, AcceptanceBoundaryIsBitExact) {
  constexpr int kDims = 4;
  Image a;
  a.data = std::vector<uint8_t>(kDescriptorDim, 0);
  std::fill(a.data.begin(), a.data.begin() + kDims, 255);
  auto row_with = [](Image* image, int row, int c) {
    std::fill(image->data.begin() + row * kDescriptorDim, image->data.begin() + row * kDescriptorDim + kDims,
              static_cast<uint8_t>(c));
  };
  std::vector<Image> candidates;
  std::vector<FeatureMatches> expected;
  const MatchThresholds t{0.8f, 0.7f, false};
  for (int best = 150; best <= 255; ++best) {
    for (int second_value : {0, best - 60, best - 30, best - 10, best - 1, best}) {
      Image b;
      b.data = std::vector<uint8_t>(2 * kDescriptorDim, 0);
      row_with(&b, 0, second_value);
      row_with(&b, 1, best);
      candidates.push_back(b);
      FeatureMatches m;
      const int best_index = best > second_value ? 1 : 0;
      if (AcceptSiftMatch(255 * kDims * best, 255 * kDims * second_value, t.max_ratio, t.max_distance)) {
        m.push_back({0u, static_cast<point2D_t>(best_index)});
      }
      expected.push_back(m);
    }
  }
  DeviceImage da(a);
  std::vector<std::unique_ptr<DeviceImage>> db;
  std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>> pairs;
  for (const Image& b : candidates) {
    db.push_back(std::make_unique<DeviceImage>(b));
    pairs.emplace_back(da.view(), db.back()->view());
  }
  cuda::GpuResources resources(0, 0);
  BruteForceKernels kernels(nullptr, &resources);
  const std::vector<FeatureMatches> got = kernels.MatchPairs(pairs, t);
  int accepted = 0;
  for (size_t k = 0; k < pairs.size(); ++k) {
    EXPECT_EQ(got[k], expected[k]) << "candidate " << k;
    accepted += static_cast<int>(expected[k].size());
  }
  // Both outcomes occur, so the boundary is really crossed.
  EXPECT_GT(accepted, 10);
  EXPECT_LT(accepted, static_cast<int>(pairs.size()) - 10);
}

}  // namespace
}  // namespace cashash
