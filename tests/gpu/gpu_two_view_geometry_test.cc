// GPU RANSAC (F and H on the device, E and the decision on the CPU) against
// the CPU path on the same matches: synthetic pairs with known geometry and
// outlier ratios, and, when CASHASH_VERIFY_PAIRS_FILE names a verification
// pairs file (scripts/bench/dump_verification_pairs), real pairs. Inlier
// counts must agree within a few percent, configurations on all but
// borderline pairs, and the GPU's F must explain the CPU's inliers.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "../synthetic_two_view.h"
#include "cashash/batch_verifier.h"
#include "cashash/fundamental_matrix.h"
#include "cashash/pair_id.h"
#include "cashash/two_view_geometry.h"
#include "cashash/verification_pairs_file.h"
#include "cashash_cuda/gpu_feature_matcher.h"
#include "cashash_cuda/gpu_two_view_geometry.h"

namespace cashash {
namespace {

using testing_support::MakeScene;
using testing_support::SceneOptions;
using testing_support::SyntheticScene;

#define SKIP_WITHOUT_CUDA_DEVICE()                                                   \
  do {                                                                               \
    std::string reason;                                                              \
    if (cuda::NumCudaDevices() == 0 || !cuda::CudaDeviceUsable(0, &reason)) {        \
      GTEST_SKIP() << "no CUDA device: " << (reason.empty() ? "none found" : reason); \
    }                                                                                \
  } while (0)

// Counts agree within max(slack, ratio x reference).
bool Close(int a, int reference, double ratio = 0.03, int slack = 3) {
  return std::abs(a - reference) <= std::max(static_cast<double>(slack), ratio * reference);
}

// RMS Sampson distance (pixels) of `F` (pixel coordinates) over the matches
// marked in `mask`.
double RmsSampsonPixels(const Eigen::Matrix3d& F, const PointPairs& pixels, const std::vector<char>& mask) {
  double f[9];
  RowMajor(F, f);
  double sum = 0;
  int n = 0;
  for (size_t i = 0; i < pixels.size(); ++i) {
    if (!mask[i]) continue;
    sum += SampsonSquaredError(f, pixels.x1[i], pixels.y1[i], pixels.x2[i], pixels.y2[i]);
    ++n;
  }
  return n > 0 ? std::sqrt(sum / n) : 0.0;
}

struct Case {
  SyntheticScene scene;
  std::string name;
  bool planar;
};

std::vector<Case> SyntheticCases() {
  std::vector<Case> cases;
  for (const bool planar : {false, true}) {
    for (const double outliers : {0.1, 0.3, 0.5, 0.7}) {
      for (unsigned seed = 1; seed <= 2; ++seed) {
        SceneOptions o;
        o.planar = planar;
        o.outlier_ratio = outliers;
        o.seed = seed * 17 + static_cast<unsigned>(outliers * 10);
        o.num_inliers = 300 + 200 * static_cast<int>(seed);
        char name[64];
        std::snprintf(name, sizeof(name), "%s outliers %.0f%% seed %u", planar ? "planar" : "general",
                      100 * outliers, seed);
        cases.push_back({MakeScene(o), name, planar});
      }
    }
  }
  return cases;
}

TEST(GpuTwoViewRansac, SyntheticPairsAgreeWithCpu) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const std::vector<Case> cases = SyntheticCases();
  TwoViewGeometryOptions options;
  std::vector<TwoViewPoints> points;
  std::vector<uint64_t> seeds;
  for (size_t k = 0; k < cases.size(); ++k) {
    points.push_back(PrepareTwoViewPoints(cases[k].scene.points1, cases[k].scene.points2, cases[k].scene.matches));
    seeds.push_back(PairRandomSeed(3, ImagePair(1, static_cast<image_t>(k + 2))));
  }
  std::vector<const TwoViewPoints*> pointers;
  for (const TwoViewPoints& p : points) pointers.push_back(&p);
  cuda::GpuTwoViewRansac ransac(options, 0);
  std::vector<TwoViewModelEstimate> F, H;
  ransac.Estimate(pointers, seeds, &F, &H);
  ASSERT_EQ(F.size(), cases.size());

  std::printf("%-28s %7s %7s %7s %7s %7s %8s %8s %7s\n", "case", "matches", "F cpu", "F gpu", "H cpu", "H gpu",
              "rms cpu", "rms gpu", "trials");
  for (size_t k = 0; k < cases.size(); ++k) {
    SCOPED_TRACE(cases[k].name);
    TwoViewGeometryOptions pair_options = options;
    pair_options.random_seed = seeds[k];
    const TwoViewModelEstimate cpu_F = EstimateFundamental(points[k], pair_options);
    const TwoViewModelEstimate cpu_H = EstimateHomography(points[k], pair_options);
    // RMS Sampson distance over the true inliers (the noise is 0.3 px).
    std::vector<char> truth(cases[k].scene.is_inlier.begin(), cases[k].scene.is_inlier.end());
    const double rms = F[k].success ? RmsSampsonPixels(F[k].model, points[k].pixels, truth) : -1;
    const double cpu_rms = cpu_F.success ? RmsSampsonPixels(cpu_F.model, points[k].pixels, truth) : -1;
    std::printf("%-28s %7zu %7d %7d %7d %7d %8.3f %8.3f %7d\n", cases[k].name.c_str(), points[k].pixels.size(),
                cpu_F.num_inliers, F[k].num_inliers, cpu_H.num_inliers, H[k].num_inliers, cpu_rms, rms,
                F[k].num_trials);
    ASSERT_TRUE(F[k].success);
    ASSERT_EQ(F[k].inlier_mask.size(), points[k].pixels.size());
    int mask_count = 0;
    for (char c : F[k].inlier_mask) mask_count += c;
    EXPECT_EQ(mask_count, F[k].num_inliers);
    if (cases[k].planar) {
      ASSERT_TRUE(H[k].success);
      EXPECT_TRUE(Close(H[k].num_inliers, cpu_H.num_inliers)) << H[k].num_inliers << " vs " << cpu_H.num_inliers;
    } else {
      EXPECT_TRUE(Close(F[k].num_inliers, cpu_F.num_inliers)) << F[k].num_inliers << " vs " << cpu_F.num_inliers;
      // The GPU's F explains the true inliers about as well as the CPU's.
      EXPECT_LE(rms, 1.25 * cpu_rms + 0.25);
      // And finds the true inliers.
      int true_kept = 0, true_total = 0;
      for (size_t i = 0; i < cases[k].scene.is_inlier.size(); ++i) {
        true_total += cases[k].scene.is_inlier[i];
        true_kept += cases[k].scene.is_inlier[i] && F[k].inlier_mask[i];
      }
      EXPECT_GT(static_cast<double>(true_kept) / true_total, 0.95);
    }
    EXPECT_GE(F[k].num_trials, options.min_num_trials);
    EXPECT_LE(F[k].num_trials, options.max_num_trials);
  }
}

TEST(GpuTwoViewRansac, SameSeedSameResult) {
  SKIP_WITHOUT_CUDA_DEVICE();
  SceneOptions o;
  o.outlier_ratio = 0.6;
  const SyntheticScene scene = MakeScene(o);
  const TwoViewPoints points = PrepareTwoViewPoints(scene.points1, scene.points2, scene.matches);
  // The same pair three times with one seed, once with another.
  const std::vector<const TwoViewPoints*> pointers = {&points, &points, &points, &points};
  const std::vector<uint64_t> seeds = {11, 11, 11, 12};
  cuda::GpuTwoViewRansac ransac(TwoViewGeometryOptions(), 0);
  std::vector<TwoViewModelEstimate> F, H, F2, H2;
  ransac.Estimate(pointers, seeds, &F, &H);
  ransac.Estimate(pointers, seeds, &F2, &H2);
  for (size_t k = 0; k < 3; ++k) {
    for (const auto* other : {&F[0], &F2[k]}) {
      EXPECT_EQ(F[k].num_inliers, other->num_inliers);
      EXPECT_EQ(F[k].inlier_mask, other->inlier_mask);
      EXPECT_EQ(F[k].model, other->model);
    }
    EXPECT_EQ(H[k].inlier_mask, H2[k].inlier_mask);
    EXPECT_EQ(H[k].model, H2[k].model);
  }
  EXPECT_TRUE(Close(F[3].num_inliers, F[0].num_inliers));
}

TEST(GpuTwoViewRansac, DegenerateInputsFailCleanly) {
  SKIP_WITHOUT_CUDA_DEVICE();
  // All matches at one point, exactly seven matches, and pure noise.
  std::vector<TwoViewPoints> points(3);
  auto fill = [](TwoViewPoints* p, size_t n, auto position) {
    std::vector<Eigen::Vector2d> p1, p2;
    FeatureMatches m;
    for (size_t i = 0; i < n; ++i) {
      const auto [a, b] = position(i);
      p1.push_back(a);
      p2.push_back(b);
      m.push_back({static_cast<point2D_t>(i), static_cast<point2D_t>(i)});
    }
    *p = PrepareTwoViewPoints(p1, p2, m);
  };
  fill(&points[0], 50, [](size_t) { return std::make_pair(Eigen::Vector2d(10, 10), Eigen::Vector2d(20, 20)); });
  fill(&points[1], 7, [](size_t i) {
    return std::make_pair(Eigen::Vector2d(100.0 * i, 37.0 * i * i), Eigen::Vector2d(90.0 * i + 3, 41.0 * i));
  });
  fill(&points[2], 200, [](size_t i) {
    const double a = std::sin(12.9898 * i) * 43758.5453, b = std::sin(78.233 * i) * 12345.678;
    return std::make_pair(Eigen::Vector2d(std::fmod(std::fabs(a), 1000.0), std::fmod(std::fabs(b), 800.0)),
                          Eigen::Vector2d(std::fmod(std::fabs(a * 1.7), 1000.0), std::fmod(std::fabs(b * 2.3), 800.0)));
  });
  const std::vector<const TwoViewPoints*> pointers = {&points[0], &points[1], &points[2]};
  cuda::GpuTwoViewRansac ransac(TwoViewGeometryOptions(), 0);
  std::vector<TwoViewModelEstimate> F, H;
  ransac.Estimate(pointers, {1, 2, 3}, &F, &H);
  EXPECT_FALSE(F[0].success);
  EXPECT_FALSE(H[0].success);
  EXPECT_LT(F[2].num_inliers, 100);  // noise: at most a chance subset
  EXPECT_LT(H[2].num_inliers, 30);
}

// The whole verifier (GPU F/H, CPU E and decision) against the CPU one.
TEST(GpuBatchVerifier, SameConfigurationsAsCpuOnSyntheticPairs) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const std::vector<Case> cases = SyntheticCases();
  const Camera with_prior = cases[0].scene.MakeCamera(true), without = cases[0].scene.MakeCamera(false);
  std::vector<VerificationPair> pairs;
  for (size_t k = 0; k < cases.size(); ++k) {
    for (const Camera* camera : {&with_prior, &without}) {
      VerificationPair p;
      p.camera1 = p.camera2 = camera;
      p.points1 = &cases[k].scene.points1;
      p.points2 = &cases[k].scene.points2;
      p.matches = &cases[k].scene.matches;
      p.random_seed = 1000 + pairs.size();
      pairs.push_back(p);
    }
  }
  // Fewer matches than min_num_inliers: DEGENERATE without estimation.
  FeatureMatches few(cases[0].scene.matches.begin(), cases[0].scene.matches.begin() + 10);
  VerificationPair tiny = pairs[0];
  tiny.matches = &few;
  pairs.push_back(tiny);

  const TwoViewGeometryOptions options;
  const std::vector<TwoViewGeometry> cpu = CreateCpuBatchVerifier(options, -1)->Verify(pairs);
  const std::vector<TwoViewGeometry> gpu = cuda::CreateGpuBatchVerifier(options, 0, -1)->Verify(pairs);
  ASSERT_EQ(gpu.size(), pairs.size());
  for (size_t k = 0; k < pairs.size(); ++k) {
    SCOPED_TRACE(k + 1 == pairs.size() ? std::string("tiny") : cases[k / 2].name + (k % 2 ? "" : " priors"));
    EXPECT_EQ(gpu[k].config, cpu[k].config);
    EXPECT_TRUE(Close(static_cast<int>(gpu[k].inlier_matches.size()), static_cast<int>(cpu[k].inlier_matches.size())))
        << gpu[k].inlier_matches.size() << " vs " << cpu[k].inlier_matches.size();
  }
  EXPECT_EQ(gpu.back().config, kDegenerate);
}

TEST(GpuBatchVerifier, RealPairsAgreeWithCpu) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const char* path = std::getenv("CASHASH_VERIFY_PAIRS_FILE");
  if (path == nullptr || *path == '\0') {
    GTEST_SKIP() << "CASHASH_VERIFY_PAIRS_FILE is not set (a file from scripts/bench/dump_verification_pairs)";
  }
  const std::vector<StoredVerificationPair> stored = ReadVerificationPairsFile(path);
  ASSERT_FALSE(stored.empty());
  std::vector<VerificationPair> pairs;
  for (const StoredVerificationPair& p : stored) pairs.push_back(p.View(PairRandomSeed(0, p.pair)));
  const TwoViewGeometryOptions options;
  const std::vector<TwoViewGeometry> cpu = CreateCpuBatchVerifier(options, -1)->Verify(pairs);
  const std::vector<TwoViewGeometry> gpu = cuda::CreateGpuBatchVerifier(options, 0, -1)->Verify(pairs);

  // F alone, GPU against CPU, and how well the GPU's F explains the CPU's
  // F inliers.
  std::vector<TwoViewPoints> points;
  std::vector<const TwoViewPoints*> pointers;
  std::vector<uint64_t> seeds;
  points.reserve(pairs.size());
  for (const VerificationPair& p : pairs) {
    points.push_back(PrepareTwoViewPoints(*p.points1, *p.points2, *p.matches));
    pointers.push_back(&points.back());
    seeds.push_back(p.random_seed);
  }
  cuda::GpuTwoViewRansac ransac(options, 0);
  std::vector<TwoViewModelEstimate> F, H;
  ransac.Estimate(pointers, seeds, &F, &H);

  int same_config = 0, verified = 0, close_inliers = 0, f_compared = 0, f_close = 0, f_explains = 0;
  std::printf("%-12s %7s %6s %6s %8s %8s %7s %7s %8s %8s\n", "pair", "matches", "cfg", "cfg", "inliers", "inliers",
              "F cpu", "F gpu", "rms cpu", "rms gpu");
  std::printf("%-12s %7s %6s %6s %8s %8s\n", "", "", "cpu", "gpu", "cpu", "gpu");
  for (size_t k = 0; k < pairs.size(); ++k) {
    TwoViewGeometryOptions pair_options = options;
    pair_options.random_seed = pairs[k].random_seed;
    const TwoViewModelEstimate cpu_F = EstimateFundamental(points[k], pair_options);
    // How well each F explains the CPU's F inliers.
    const double rms = F[k].success && cpu_F.success ? RmsSampsonPixels(F[k].model, points[k].pixels, cpu_F.inlier_mask)
                                                     : -1;
    const double cpu_rms = cpu_F.success ? RmsSampsonPixels(cpu_F.model, points[k].pixels, cpu_F.inlier_mask) : -1;
    const int ci = static_cast<int>(cpu[k].inlier_matches.size()), gi = static_cast<int>(gpu[k].inlier_matches.size());
    std::printf("%5u-%-6u %7zu %6d %6d %8d %8d %7d %7d %8.3f %8.3f\n", stored[k].pair.first, stored[k].pair.second,
                pairs[k].matches->size(), cpu[k].config, gpu[k].config, ci, gi, cpu_F.num_inliers, F[k].num_inliers,
                cpu_rms, rms);
    same_config += cpu[k].config == gpu[k].config;
    if (cpu[k].config >= kCalibrated && cpu[k].config == gpu[k].config) {
      ++verified;
      close_inliers += Close(gi, ci, 0.05, 5);
    }
    if (cpu_F.num_inliers >= 50) {
      ++f_compared;
      f_close += Close(F[k].num_inliers, cpu_F.num_inliers, 0.05, 5);
      f_explains += rms >= 0 && rms <= 1.25 * cpu_rms + 0.25;
    }
  }
  const double n = static_cast<double>(pairs.size());
  std::printf("same config %d/%zu, verified pairs with inlier counts within 5%%: %d/%d, "
              "F inlier counts within 5%%: %d/%d, GPU F explains CPU F inliers (rms <= 1.25 cpu rms + 0.25 px): %d/%d\n",
              same_config, pairs.size(), close_inliers, verified, f_close, f_compared, f_explains, f_compared);
  EXPECT_GE(same_config, 0.9 * n);
  EXPECT_GE(close_inliers, 0.9 * verified);
  EXPECT_GE(f_close, 0.9 * f_compared);
  EXPECT_GE(f_explains, 0.95 * f_compared);
}

}  // namespace
}  // namespace cashash
