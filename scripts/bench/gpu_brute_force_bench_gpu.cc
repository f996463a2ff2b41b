// Throughput of the exact GPU brute-force matcher: pairs per second at 2048,
// 8192 and 16384 features per image, both directions, ratio test and
// cross-check (matching only; descriptors already on the device).
//
// Synthetic SIFT-like descriptors: |gaussian| components normalised to 512
// and capped at 255; half of each image's rows are noisy copies of rows of
// a shared pool, so pairs have real matches.
//
// Usage: gpu_brute_force_bench_gpu [repetitions=10]
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "cashash_cuda/matching/brute_force_matcher.cuh"
#include "cashash_cuda/utils/cuda_check.cuh"

namespace {

using cashash::kDescriptorDim;
using namespace cashash::cuda;

void FillDescriptor(std::mt19937& rng, uint8_t* out) {
  std::normal_distribution<float> normal(0.f, 1.f);
  float v[kDescriptorDim];
  float norm = 0.f;
  for (float& x : v) {
    x = std::fabs(normal(rng));
    norm += x * x;
  }
  norm = std::sqrt(norm);
  for (int d = 0; d < kDescriptorDim; ++d) out[d] = static_cast<uint8_t>(std::min(255.f, std::round(512.f * v[d] / norm)));
}

// num_images images of n rows, generated on all cores.
std::vector<std::vector<uint8_t>> MakeImages(int num_images, int n) {
  std::vector<uint8_t> pool(static_cast<size_t>(n) * kDescriptorDim);
  {
    std::mt19937 rng(7);
    for (int i = 0; i < n; ++i) FillDescriptor(rng, pool.data() + static_cast<size_t>(i) * kDescriptorDim);
  }
  std::vector<std::vector<uint8_t>> images(num_images);
  std::vector<std::thread> threads;
  for (int m = 0; m < num_images; ++m) {
    threads.emplace_back([&, m] {
      std::mt19937 rng(100 + m);
      std::uniform_int_distribution<int> noise(-4, 4);
      std::vector<uint8_t>& image = images[m];
      image.resize(pool.size());
      for (int i = 0; i < n; ++i) {
        uint8_t* row = image.data() + static_cast<size_t>(i) * kDescriptorDim;
        if (i % 2 == 0) {
          FillDescriptor(rng, row);
        } else {
          const uint8_t* src = pool.data() + static_cast<size_t>(i) * kDescriptorDim;
          for (int d = 0; d < kDescriptorDim; ++d) row[d] = static_cast<uint8_t>(std::clamp(src[d] + noise(rng), 0, 255));
        }
      }
    });
  }
  for (auto& t : threads) t.join();
  return images;
}

struct Row {
  int features = 0;
  int pairs = 0;
  double kernel_ms = 0;       // median per batch, device work only
  double end_to_end_ms = 0;   // MatchPairs: launch, copy back, host vectors
  double matches_per_pair = 0;
};

Row Measure(int n, int num_images, int repetitions) {
  const std::vector<std::vector<uint8_t>> images = MakeImages(num_images, n);
  std::vector<uint8_t*> device(num_images);
  for (int m = 0; m < num_images; ++m) {
    CUDA_CHECK(cudaMalloc(&device[m], images[m].size()));
    CUDA_CHECK(cudaMemcpy(device[m], images[m].data(), images[m].size(), cudaMemcpyHostToDevice));
  }
  std::vector<std::pair<DeviceDescriptors, DeviceDescriptors>> pairs;
  for (int i = 0; i < num_images; ++i) {
    for (int j = i + 1; j < num_images; ++j) pairs.push_back({{device[i], n}, {device[j], n}});
  }
  const MatchThresholds thresholds;  // 0.8, 0.7, cross-check

  // Output buffers for the kernel-only timing.
  const size_t per_pair_ints = BruteForceKernels::MatchPairsScratchBytes(n, n) / 4;
  int* out = nullptr;
  CUDA_CHECK(cudaMalloc(&out, per_pair_ints * pairs.size() * sizeof(int)));
  std::vector<BestTwoProblem> best_two;
  std::vector<MutualMatchProblem> mutual;
  for (size_t k = 0; k < pairs.size(); ++k) {
    int* base = out + k * per_pair_ints;
    BestTwoProblem p12, p21;
    p12.a = p21.b = pairs[k].first.data;
    p12.b = p21.a = pairs[k].second.data;
    p12.n_a = p12.n_b = p21.n_a = p21.n_b = n;
    p12.best_dot = base;
    p12.second_dot = base + n;
    p12.best_idx = base + 2 * n;
    p21.best_dot = base + 3 * n;
    p21.second_dot = base + 4 * n;
    p21.best_idx = base + 5 * n;
    best_two.push_back(p12);
    best_two.push_back(p21);
    MutualMatchProblem m;
    m.best_dot12 = p12.best_dot;
    m.second_dot12 = p12.second_dot;
    m.best_idx12 = p12.best_idx;
    m.best_dot21 = p21.best_dot;
    m.second_dot21 = p21.second_dot;
    m.best_idx21 = p21.best_idx;
    m.matches = reinterpret_cast<uint32_t*>(base + 6 * n);
    m.num_matches = base + 8 * n;
    m.n1 = m.n2 = n;
    mutual.push_back(m);
  }

  GpuResources resources(0, 0);
  BruteForceKernels kernels(nullptr, &resources);
  cudaEvent_t start, stop;
  CUDA_CHECK(cudaEventCreate(&start));
  CUDA_CHECK(cudaEventCreate(&stop));
  std::vector<double> times;
  for (int r = 0; r < repetitions + 2; ++r) {
    CUDA_CHECK(cudaEventRecord(start, kernels.stream()));
    kernels.EnqueueBestTwo(best_two);
    kernels.EnqueueMutualMatches(mutual, thresholds);
    CUDA_CHECK(cudaEventRecord(stop, kernels.stream()));
    CUDA_CHECK(cudaEventSynchronize(stop));
    float ms = 0;
    CUDA_CHECK(cudaEventElapsedTime(&ms, start, stop));
    if (r >= 2) times.push_back(ms);  // two warm-up batches
  }
  std::sort(times.begin(), times.end());

  Row row;
  row.features = n;
  row.pairs = static_cast<int>(pairs.size());
  row.kernel_ms = times[times.size() / 2];
  std::vector<double> e2e;
  size_t matches = 0;
  for (int r = 0; r < 3; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    const std::vector<cashash::FeatureMatches> result = kernels.MatchPairs(pairs, thresholds);
    e2e.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    matches = 0;
    for (const auto& m : result) matches += m.size();
  }
  std::sort(e2e.begin(), e2e.end());
  row.end_to_end_ms = e2e[1];
  row.matches_per_pair = static_cast<double>(matches) / pairs.size();

  CUDA_CHECK(cudaEventDestroy(start));
  CUDA_CHECK(cudaEventDestroy(stop));
  CUDA_CHECK(cudaFree(out));
  for (uint8_t* d : device) CUDA_CHECK(cudaFree(d));
  return row;
}

}  // namespace

int main(int argc, char** argv) {
  const int repetitions = argc > 1 ? std::max(1, std::atoi(argv[1])) : 10;
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess || count == 0) {
    std::printf("no CUDA device\n");
    return 77;
  }
  cudaDeviceProp prop;
  CUDA_CHECK(cudaGetDeviceProperties(&prop, 0));
  std::printf("device: %s, %d SMs\n", prop.name, prop.multiProcessorCount);

  std::vector<Row> rows;
  for (const auto& [n, images] : std::vector<std::pair<int, int>>{{2048, 32}, {8192, 16}, {16384, 12}}) {
    rows.push_back(Measure(n, images, repetitions));
    const Row& r = rows.back();
    std::printf("n=%d pairs=%d kernel %.3f ms/batch, MatchPairs %.3f ms/batch\n", r.features, r.pairs, r.kernel_ms,
                r.end_to_end_ms);
    std::fflush(stdout);
  }
  std::printf("\n%9s %6s %14s %12s %16s %12s\n", "features", "pairs", "kernel pair/s", "int8 TOPS", "MatchPairs pr/s",
              "matches/pr");
  for (const Row& r : rows) {
    // One pair: n*n*128 multiply-adds in each of the two directions.
    const double ops = 2.0 * 2.0 * r.features * static_cast<double>(r.features) * kDescriptorDim * r.pairs;
    std::printf("%9d %6d %14.0f %12.1f %16.0f %12.1f\n", r.features, r.pairs, r.pairs / (r.kernel_ms * 1e-3),
                ops / (r.kernel_ms * 1e-3) / 1e12, r.pairs / (r.end_to_end_ms * 1e-3), r.matches_per_pair);
  }
  return 0;
}
