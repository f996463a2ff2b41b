// Throughput of the 5-point solver alone, on the device (one thread per
// sample, as in the E RANSAC kernel) and on one host core, to tell how much
// of E-RANSAC's device time the minimal solve is: set its solves per second
// beside the trials per second `GPU verification:` reports for E.
//
// Samples are drawn as RANSAC draws them, from synthetic calibrated pairs
// (tests/support/synthetic_two_view.h) with a share of outliers: five distinct
// correspondences at random, in normalised camera coordinates.
//
// Usage: five_point_bench_gpu [--samples N] [--outliers R] [--repeats K]
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <random>
#include <vector>

#include "../../tests/support/synthetic_two_view.h"
#include "cashash/geometry/five_point_solver.h"
#include "cashash/geometry/two_view_geometry.h"
#include "cashash_cuda/geometry/ransac.cuh"

namespace {

using cashash::testing_support::MakeScene;
using cashash::testing_support::SceneOptions;

// `count` samples of 20 floats (x1, y1, x2, y2 five times).
std::vector<float> DrawSamples(int count, double outlier_ratio) {
  std::vector<float> samples;
  samples.reserve(static_cast<size_t>(count) * 20);
  std::mt19937 rng(7);
  unsigned seed = 1;
  while (static_cast<int>(samples.size() / 20) < count) {
    SceneOptions o;
    o.seed = seed++;
    o.num_inliers = 400;
    o.outlier_ratio = outlier_ratio;
    const auto scene = MakeScene(o);
    const cashash::Camera camera = scene.MakeCamera(true);
    const cashash::EssentialPoints points =
        cashash::PrepareEssentialPoints(camera, camera, scene.Pairs(), cashash::TwoViewGeometryOptions());
    const auto& w = points.world;
    const int n = static_cast<int>(w.fx1.size());
    std::uniform_int_distribution<int> pick(0, n - 1);
    for (int s = 0; s < 256 && static_cast<int>(samples.size() / 20) < count; ++s) {
      int idx[5];
      for (int k = 0; k < 5; ++k) {
        bool repeated;
        do {
          idx[k] = pick(rng);
          repeated = false;
          for (int j = 0; j < k; ++j) repeated |= idx[j] == idx[k];
        } while (repeated);
        samples.insert(samples.end(), {w.fx1[idx[k]], w.fy1[idx[k]], w.fx2[idx[k]], w.fy2[idx[k]]});
      }
    }
  }
  return samples;
}

}  // namespace

int main(int argc, char** argv) {
  int num_samples = 1 << 20, repeats = 3;
  double outliers = 0.5;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--samples")) num_samples = std::atoi(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--outliers")) outliers = std::atof(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--repeats")) repeats = std::atoi(argv[i + 1]);
    else {
      std::fprintf(stderr, "unknown option %s\n", argv[i]);
      return 2;
    }
  }
  const std::vector<float> samples = DrawSamples(num_samples, outliers);
  std::vector<double> models(static_cast<size_t>(num_samples) * 90);
  std::vector<int> counts(num_samples);
  float best_ms = 1e30f;
  try {
    for (int r = 0; r < repeats; ++r) {
      const float ms =
          cashash::cuda::EssentialFivePointOnDevice(samples.data(), num_samples, models.data(), counts.data());
      if (ms < best_ms) best_ms = ms;
    }
  } catch (const std::exception& error) {
    std::fprintf(stderr, "the GPU solver failed: %s\n", error.what());
  }
  long long solutions = 0;
  for (int c : counts) solutions += c;

  // One host core, on a slice.
  const int host_samples = std::min(num_samples, 20000);
  const auto t0 = std::chrono::steady_clock::now();
  long long host_solutions = 0;
  for (int i = 0; i < host_samples; ++i) {
    double pairs[20];
    for (int k = 0; k < 20; ++k) pairs[k] = samples[20 * static_cast<size_t>(i) + k];
    double out[10][9];
    host_solutions += cashash::five_point::EssentialFromFivePoints(pairs, out);
  }
  const double host_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  std::printf("| solver | samples | outliers | solutions per sample | seconds | solves/s |\n|---|---:|---:|---:|---:|---:|\n");
  if (best_ms < 1e30f) {
    std::printf("| device, one thread per sample (best of %d) | %d | %.2f | %.2f | %.4f | %.3g |\n", repeats,
                num_samples, outliers, static_cast<double>(solutions) / num_samples, best_ms * 1e-3,
                num_samples / (best_ms * 1e-3));
  }
  std::printf("| host, one core | %d | %.2f | %.2f | %.4f | %.3g |\n", host_samples, outliers,
              static_cast<double>(host_solutions) / host_samples, host_s, host_samples / host_s);
  return 0;
}
