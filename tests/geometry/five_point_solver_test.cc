// The portable 5-point solver (five_point_solver.h, which the GPU RANSAC
// runs per thread) in its host instantiation against the Eigen solver of
// essential_matrix.cc, its Sturm root finder on known polynomials, and the
// host helper that prepares E's points for both verifiers.
#include "cashash/geometry/five_point_solver.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <random>
#include <vector>

#include <Eigen/Dense>

#include "cashash/geometry/camera_models.h"
#include "cashash/geometry/essential_matrix.h"
#include "cashash/geometry/ransac.h"
#include "cashash/geometry/two_view_geometry.h"
#include "ordered_draws.h"
#include "synthetic_two_view.h"

namespace cashash {
namespace {

using testing_support::MakeScene;
using testing_support::SceneOptions;
using testing_support::SyntheticScene;

PointPairs WorldPairs(const SyntheticScene& scene) {
  return PrepareEssentialPoints(scene.MakeCamera(true), scene.MakeCamera(true), scene.Pairs(),
                                TwoViewGeometryOptions())
      .world;
}

Eigen::Matrix3d FromRowMajor(const double* v) {
  Eigen::Matrix3d m;
  m << v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8];
  return m;
}

// Distance up to scale and sign.
double Distance(Eigen::Matrix3d a, Eigen::Matrix3d b) {
  a /= a.norm();
  b /= b.norm();
  return std::min((a - b).norm(), (a + b).norm());
}

int PortableFivePoint(const PointPairs& world, const int* idx, Eigen::Matrix3d* out) {
  double pairs[20];
  for (int k = 0; k < 5; ++k) {
    pairs[4 * k] = world.x1[idx[k]];
    pairs[4 * k + 1] = world.y1[idx[k]];
    pairs[4 * k + 2] = world.x2[idx[k]];
    pairs[4 * k + 3] = world.y2[idx[k]];
  }
  double models[five_point::kMaxSolutions][9];
  const int n = five_point::EssentialFromFivePoints(pairs, models);
  for (int m = 0; m < n; ++m) out[m] = FromRowMajor(models[m]);
  return n;
}

// How many of `a` have a match in `b` within `tolerance`.
int Matched(const Eigen::Matrix3d* a, int na, const Eigen::Matrix3d* b, int nb, double tolerance) {
  int matched = 0;
  for (int i = 0; i < na; ++i) {
    double best = 1e9;
    for (int j = 0; j < nb; ++j) best = std::min(best, Distance(a[i], b[j]));
    matched += best < tolerance;
  }
  return matched;
}

TEST(FivePointSolver, ExactSamplesGiveTheTrueEAndTheCpuSolutions) {
  SceneOptions opts;
  opts.num_inliers = 40;
  opts.outlier_ratio = 0;
  opts.noise_px = 0;
  int total_cpu = 0, total_portable = 0, matched_cpu = 0, matched_portable = 0, within_1e7 = 0, samples = 0;
  for (unsigned seed = 1; seed <= 30; ++seed) {
    opts.seed = seed;
    const SyntheticScene scene = MakeScene(opts);
    const PointPairs world = WorldPairs(scene);
    for (int s = 0; s < 5; ++s) {
      const int idx[5] = {s, s + 7, s + 14, s + 21, s + 28};
      Eigen::Matrix3d cpu[10], portable[10];
      const int nc = EssentialFivePoint(world, idx, 5, cpu);
      const int np = PortableFivePoint(world, idx, portable);
      ASSERT_GE(np, 1) << "seed " << seed << " sample " << s;
      double best = 1e9;
      for (int m = 0; m < np; ++m) {
        best = std::min(best, Distance(portable[m], scene.TrueE()));
        // Every solution is essential (singular values s, s, 0) and fits the sample.
        const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(portable[m]).singularValues();
        EXPECT_NEAR(sv(0), sv(1), 1e-5 * sv(0));
        EXPECT_NEAR(sv(2), 0.0, 1e-5 * sv(0));
        for (int k = 0; k < 5; ++k) {
          const Eigen::Vector3d x1(world.x1[idx[k]], world.y1[idx[k]], 1), x2(world.x2[idx[k]], world.y2[idx[k]], 1);
          EXPECT_NEAR(x2.dot(portable[m] * x1), 0.0, 1e-9);
        }
      }
      // Exact but for the conditioning of rare samples (1e-5 seen).
      EXPECT_LT(best, 1e-4) << "seed " << seed << " sample " << s;
      within_1e7 += best < 1e-7;
      ++samples;
      total_cpu += nc;
      total_portable += np;
      matched_cpu += Matched(cpu, nc, portable, np, 1e-6);
      matched_portable += Matched(portable, np, cpu, nc, 1e-6);
    }
  }
  std::printf("solutions: cpu %d (%d found by the portable solver), portable %d (%d found by the cpu)\n", total_cpu,
              matched_cpu, total_portable, matched_portable);
  EXPECT_GE(within_1e7, 0.97 * samples);
  // The same solution sets, but for rare ill-conditioned roots.
  EXPECT_GE(matched_cpu, 0.99 * total_cpu);
  EXPECT_GE(matched_portable, 0.99 * total_portable);
}

TEST(FivePointSolver, NoisySamplesWithOutliersMatchTheCpuSolver) {
  SceneOptions opts;
  opts.num_inliers = 200;
  opts.outlier_ratio = 0.5;
  int total_cpu = 0, total_portable = 0, matched_cpu = 0, matched_portable = 0;
  std::mt19937 rng(5);
  for (unsigned seed = 1; seed <= 10; ++seed) {
    opts.seed = seed;
    const SyntheticScene scene = MakeScene(opts);
    const PointPairs world = WorldPairs(scene);
    for (int s = 0; s < 100; ++s) {
      int idx[5];
      for (int k = 0; k < 5; ++k) {
        for (;;) {
          idx[k] = static_cast<int>(rng() % world.size());
          if (std::find(idx, idx + k, idx[k]) == idx + k) break;
        }
      }
      Eigen::Matrix3d cpu[10], portable[10];
      const int nc = EssentialFivePoint(world, idx, 5, cpu);
      const int np = PortableFivePoint(world, idx, portable);
      total_cpu += nc;
      total_portable += np;
      matched_cpu += Matched(cpu, nc, portable, np, 1e-5);
      matched_portable += Matched(portable, np, cpu, nc, 1e-5);
    }
  }
  std::printf("noisy samples: cpu %d (%d found by the portable solver), portable %d (%d found by the cpu)\n",
              total_cpu, matched_cpu, total_portable, matched_portable);
  EXPECT_GE(matched_cpu, 0.98 * total_cpu);
  EXPECT_GE(matched_portable, 0.98 * total_portable);
}

TEST(FivePointSolver, LeastSquaresBasisMatchesTheCpuRefit) {
  for (const double noise : {0.0, 0.5}) {
    SceneOptions opts;
    opts.num_inliers = 150;
    opts.outlier_ratio = 0;
    opts.noise_px = noise;
    for (unsigned seed = 1; seed <= 10; ++seed) {
      opts.seed = seed;
      const SyntheticScene scene = MakeScene(opts);
      const PointPairs world = WorldPairs(scene);
      double upper[45] = {0};
      for (size_t i = 0; i < world.size(); ++i) {
        double row[9];
        five_point::EpipolarCoefficients(world.x1[i], world.y1[i], world.x2[i], world.y2[i], row);
        int k = 0;
        for (int a = 0; a < 9; ++a)
          for (int b = a; b < 9; ++b) upper[k++] += row[a] * row[b];
      }
      double basis[4][9], models[10][9];
      ASSERT_TRUE(five_point::LeastSquaresNullSpace(upper, basis));
      const int np = five_point::SolveFromBasis(basis, models);
      ASSERT_GE(np, 1);
      Eigen::Matrix3d portable[10], cpu[10];
      for (int m = 0; m < np; ++m) portable[m] = FromRowMajor(models[m]);
      std::vector<int> all(world.size());
      for (size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
      const int nc = EssentialFivePoint(world, all.data(), static_cast<int>(all.size()), cpu);
      // Exact points: the true E. Noisy ones: whatever the CPU refit gives
      // (the least-squares null space is then only near the true E).
      if (noise == 0) {
        double best = 1e9;
        for (int m = 0; m < np; ++m) best = std::min(best, Distance(portable[m], scene.TrueE()));
        EXPECT_LT(best, 1e-7) << "seed " << seed;
      }
      EXPECT_EQ(Matched(cpu, nc, portable, np, 1e-6), nc) << "seed " << seed << " noise " << noise;
    }
  }
}

TEST(FivePointSolver, NullSpaceIsOrthonormalAndAnnihilatesTheRows) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uni(-1, 1);
  for (int trial = 0; trial < 50; ++trial) {
    double rows[5][9], basis[4][9];
    for (auto& row : rows) {
      const auto u = testing_support::DrawLastFirst<4>([&] { return uni(rng); });
      five_point::EpipolarCoefficients(u[0], u[1], u[2], u[3], row);
    }
    ASSERT_TRUE(five_point::MinimalNullSpace(rows, basis));
    for (int a = 0; a < 4; ++a) {
      for (int b = 0; b < 4; ++b) {
        double d = 0;
        for (int i = 0; i < 9; ++i) d += basis[a][i] * basis[b][i];
        EXPECT_NEAR(d, a == b ? 1.0 : 0.0, 1e-12);
      }
      for (const auto& row : rows) {
        double d = 0;
        for (int i = 0; i < 9; ++i) d += row[i] * basis[a][i];
        EXPECT_NEAR(d, 0.0, 1e-12);
      }
    }
  }
}

// The GPU's E algorithm (the portable minimal solver and least-squares
// refit) inside the CPU's LoRansac: with the same seeds it draws the same
// samples, so it must find what the Eigen-based estimator finds.
class PortableEssentialEstimator : public EpipolarScorer {
 public:
  using Model = Eigen::Matrix3d;
  static constexpr int kSampleSize = 5;
  static constexpr int kMaxModels = 10;
  static constexpr int kMinLocalSize = 5;
  using EpipolarScorer::EpipolarScorer;
  int MinimalSolve(const int* sample, Model* models) const { return PortableFivePoint(pairs_, sample, models); }
  int LocalSolve(const std::vector<int>& inliers, Model* models) const {
    double upper[45] = {0};
    for (int i : inliers) {
      double row[9];
      five_point::EpipolarCoefficients(pairs_.x1[i], pairs_.y1[i], pairs_.x2[i], pairs_.y2[i], row);
      int k = 0;
      for (int a = 0; a < 9; ++a)
        for (int b = a; b < 9; ++b) upper[k++] += row[a] * row[b];
    }
    double basis[4][9], out[10][9];
    if (!five_point::LeastSquaresNullSpace(upper, basis)) return 0;
    const int n = five_point::SolveFromBasis(basis, out);
    for (int m = 0; m < n; ++m) models[m] = FromRowMajor(out[m]);
    return n;
  }
};

TEST(FivePointSolver, RansacWithThePortableSolverMatchesTheCpuEstimator) {
  int equal = 0, close = 0, total = 0;
  for (const double outliers : {0.2, 0.5, 0.7}) {
    for (unsigned seed = 1; seed <= 4; ++seed) {
      SceneOptions opts;
      opts.num_inliers = 300;
      opts.outlier_ratio = outliers;
      opts.seed = seed + 100;
      const SyntheticScene scene = MakeScene(opts);
      const EssentialPoints points = PrepareEssentialPoints(scene.MakeCamera(true), scene.MakeCamera(true),
                                                            scene.Pairs(), TwoViewGeometryOptions());
      RansacOptions options;
      options.max_error = points.max_error;
      options.seed = seed;
      const auto cpu = LoRansac(EssentialEstimator(points.world), options);
      const auto portable = LoRansac(PortableEssentialEstimator(points.world), options);
      ASSERT_TRUE(portable.success);
      ++total;
      equal += portable.support.num_inliers == cpu.support.num_inliers;
      close += std::abs(portable.support.num_inliers - cpu.support.num_inliers) <=
               std::max(2.0, 0.01 * cpu.support.num_inliers);
      EXPECT_LT(Distance(portable.model, scene.TrueE()), 0.1);
    }
  }
  std::printf("E LO-RANSAC, portable solver vs Eigen solver: %d/%d equal inlier counts, %d/%d within 1%%\n", equal,
              total, close, total);
  EXPECT_EQ(close, total);
  EXPECT_GE(equal, total - 2);
}

// The host helper both verifiers estimate E from.
TEST(EssentialPoints, UndistortedPointsAndFocalThreshold) {
  SceneOptions opts;
  opts.num_inliers = 60;
  const SyntheticScene scene = MakeScene(opts);
  Camera camera1 = scene.MakeCamera(true), camera2 = scene.MakeCamera(true);
  camera2.model_id = 2;  // SIMPLE_RADIAL f, cx, cy, k
  camera2.params = {800.0, 600.0, 500.0, 0.05};
  TwoViewGeometryOptions options;
  options.max_error = 3.0;
  const PointPairs pixels = scene.Pairs();
  const EssentialPoints points = PrepareEssentialPoints(camera1, camera2, pixels, options);
  ASSERT_EQ(points.world.size(), pixels.size());
  EXPECT_DOUBLE_EQ(points.max_error, 0.5 * (3.0 / 1000.0 + 3.0 / 800.0));
  for (size_t i = 0; i < pixels.size(); ++i) {
    double u1, v1, u2, v2;
    CameraImageToWorld(camera1, pixels.x1[i], pixels.y1[i], &u1, &v1);
    CameraImageToWorld(camera2, pixels.x2[i], pixels.y2[i], &u2, &v2);
    EXPECT_EQ(points.world.x1[i], u1);
    EXPECT_EQ(points.world.y2[i], v2);
    EXPECT_EQ(points.world.fx2[i], static_cast<float>(u2));
  }
  // EstimateEssential from the cameras is EstimateEssential on these points.
  options.random_seed = 9;
  const TwoViewModelEstimate a = EstimateEssential(camera1, camera1, pixels, options);
  const TwoViewModelEstimate b =
      EstimateEssential(PrepareEssentialPoints(camera1, camera1, pixels, options), options);
  EXPECT_TRUE(a.success);
  EXPECT_EQ(a.num_inliers, b.num_inliers);
  EXPECT_EQ(a.inlier_mask, b.inlier_mask);
  EXPECT_EQ(a.model, b.model);
}

}  // namespace
}  // namespace cashash
