// Throughput of the GPU matchers on a synthetic database of N images.
//
//   gpu_matching_bench_gpu [--sample FILE] [--images N] [--sizes 2048,8192,16384]
//                          [--repeats R] [--cpu_pairs P] [--bf_pairs P]
//                          [--tables T] [--bits B] [--top_k K] [--tau D]
//
// Descriptors are sampled from FILE (raw N x 128 uint8 rows, e.g. SIFT rows
// exported from a COLMAP database) or drawn synthetic; image i shares 30% of
// its features, re-noised, with image i-1 so that pairs have true matches and
// differ from each other. For each feature count it prints pairs/s of the GPU
// cascade (all pairs, ratio test + cross-check, matching only: the images are
// hashed before timing; the bucket-tile kernels and, for comparison, the
// per-query kernel), of the GPU brute force and the CPU cascade on a
// subset, the candidate statistics of the cascade, and the recall of the
// cascade against the exact brute force on the same pairs.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "cashash/matching/cascade_hashing.h"
#include "cashash/matching/cascade_matcher.h"
#include "cashash/matchers/feature_matcher.h"
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#include "../../tests/support/cascade_options.h"

namespace {

using namespace cashash;
using cashash::testing_support::CascadeOptions;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point since) { return std::chrono::duration<double>(Clock::now() - since).count(); }

struct Args {
  std::string sample;
  int images = 96;
  std::vector<int> sizes{2048, 8192, 16384};
  int repeats = 3;
  int cpu_pairs = 16;
  int bf_pairs = 128;
  int tables = 0, bits = 0, top_k = 0, tau = -1;  // 0 / -1: CascadeOptions (tests/support)
};

Args Parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string key = argv[i], value = argv[i + 1];
    if (key == "--sample") a.sample = value;
    else if (key == "--images") a.images = std::stoi(value);
    else if (key == "--repeats") a.repeats = std::stoi(value);
    else if (key == "--cpu_pairs") a.cpu_pairs = std::stoi(value);
    else if (key == "--bf_pairs") a.bf_pairs = std::stoi(value);
    else if (key == "--tables") a.tables = std::stoi(value);
    else if (key == "--bits") a.bits = std::stoi(value);
    else if (key == "--top_k") a.top_k = std::stoi(value);
    else if (key == "--tau") a.tau = std::stoi(value);
    else if (key == "--sizes") {
      a.sizes.clear();
      size_t at = 0;
      while (at < value.size()) {
        const size_t comma = value.find(',', at);
        a.sizes.push_back(std::stoi(value.substr(at, comma - at)));
        at = comma == std::string::npos ? value.size() : comma + 1;
      }
    } else {
      std::fprintf(stderr, "unknown option %s\n", key.c_str());
      std::exit(2);
    }
  }
  return a;
}

class Generator {
 public:
  Generator(const std::string& sample, uint32_t seed) : rng_(seed) {
    if (!sample.empty()) {
      std::ifstream file(sample, std::ios::binary);
      real_.assign(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
      real_.resize(real_.size() / kDescriptorDim * kDescriptorDim);
      if (real_.empty()) std::fprintf(stderr, "warning: %s gave no descriptors, using synthetic ones\n", sample.c_str());
    }
  }
  bool real() const { return !real_.empty(); }

  void Row(uint8_t* out) {
    if (real()) {
      const size_t r = std::uniform_int_distribution<size_t>(0, real_.size() / kDescriptorDim - 1)(rng_);
      std::copy_n(real_.begin() + r * kDescriptorDim, kDescriptorDim, out);
      // Perturb so that sampled rows reused across images are not identical.
      Noise(out, 3.f);
      return;
    }
    float v[kDescriptorDim];
    double norm = 0;
    for (float& x : v) {
      x = uniform_(rng_) < 0.6f ? std::exp(0.9f * normal_(rng_)) : 0.f;
      norm += double(x) * x;
    }
    const float scale = norm > 0 ? float(512.0 / std::sqrt(norm)) : 0.f;
    for (int d = 0; d < kDescriptorDim; ++d) out[d] = uint8_t(std::min(255.f, std::round(v[d] * scale)));
  }
  void Noise(uint8_t* row, float sigma) {
    for (int d = 0; d < kDescriptorDim; ++d) {
      row[d] = uint8_t(std::clamp(std::round(row[d] + sigma * normal_(rng_)), 0.f, 255.f));
    }
  }
  FeatureDescriptors Next(const FeatureDescriptors* previous, size_t n) {
    FeatureDescriptors f;
    f.data.resize(n * kDescriptorDim);
    for (size_t i = 0; i < n; ++i) {
      uint8_t* row = f.data.data() + i * kDescriptorDim;
      if (previous != nullptr && uniform_(rng_) < 0.3f) {
        const size_t from = std::uniform_int_distribution<size_t>(0, previous->rows() - 1)(rng_);
        std::copy_n(previous->row(from), kDescriptorDim, row);
        Noise(row, 6.f);
      } else {
        Row(row);
      }
    }
    return f;
  }

 private:
  std::mt19937 rng_;
  std::normal_distribution<float> normal_{0.f, 1.f};
  std::uniform_real_distribution<float> uniform_{0.f, 1.f};
  std::vector<uint8_t> real_;
};

size_t CountMatches(const std::vector<FeatureMatches>& m) {
  size_t n = 0;
  for (const auto& x : m) n += x.size();
  return n;
}

// Fraction of the exact matches that the cascade also returns.
double Recall(const std::vector<FeatureMatches>& cascade, const std::vector<FeatureMatches>& exact) {
  size_t found = 0, total = 0;
  for (size_t p = 0; p < exact.size(); ++p) {
    std::set<std::pair<uint32_t, uint32_t>> c;
    for (const auto& m : cascade[p]) c.emplace(m.point2D_idx1, m.point2D_idx2);
    for (const auto& m : exact[p]) found += c.count({m.point2D_idx1, m.point2D_idx2});
    total += exact[p].size();
  }
  return total == 0 ? 1.0 : double(found) / double(total);
}

struct Row {
  int features = 0;
  size_t pairs = 0;
  double gpu_cascade = 0, gpu_bf = 0, cpu_cascade = 0, hash_ms = 0;
  double entries_per_query = 0, within_tau_per_query = 0, matches_per_pair = 0;
  double recall = -1;
  double gpu_cascade_direct = 0;
  int direct_identical = -1;  // per-query kernel's matches == tiled kernels'
};

}  // namespace

int main(int argc, char** argv) {
  const Args args = Parse(argc, argv);
  std::string reason = "no device found";
  const bool gpu = cashash::cuda::NumCudaDevices() > 0 && cashash::cuda::CudaDeviceUsable(0, &reason);
  if (!gpu) std::printf("no usable CUDA device (%s): CPU figures only\n", reason.c_str());
  std::vector<Row> rows;
  for (const int features : args.sizes) {
    Generator generator(args.sample, 1234u + features);
    std::vector<FeatureDescriptors> images;
    for (int i = 0; i < args.images; ++i) images.push_back(generator.Next(i > 0 ? &images.back() : nullptr, features));
    std::vector<const FeatureDescriptors*> ptrs;
    for (const auto& image : images) ptrs.push_back(&image);
    const MeanDescriptor mean = ComputeMeanDescriptor(ptrs);
    std::vector<ImagePair> pairs;
    for (int i = 0; i < args.images; ++i) {
      for (int j = i + 1; j < args.images; ++j) pairs.emplace_back(i, j);
    }
    // A spread-out subset for the slower matchers: neighbours and far pairs.
    std::vector<ImagePair> subset;
    for (size_t k = 0; k < pairs.size() && subset.size() < size_t(std::max(args.cpu_pairs, args.bf_pairs)); k += 7) {
      subset.push_back(pairs[k]);
    }
    const std::vector<ImagePair> cpu_subset(subset.begin(), subset.begin() + std::min<size_t>(args.cpu_pairs, subset.size()));
    const std::vector<ImagePair> bf_subset(subset.begin(), subset.begin() + std::min<size_t>(args.bf_pairs, subset.size()));

    Row row;
    row.features = features;
    row.pairs = pairs.size();
    SiftMatchingOptions sift;
    CasHashOptions cas = CascadeOptions();
    if (args.tables > 0) cas.num_tables = args.tables;
    if (args.bits > 0) cas.bits_per_table = args.bits;
    if (args.top_k > 0) cas.top_k = args.top_k;
    if (args.tau >= 0) cas.tau = args.tau;

    // Candidate statistics of the cascade on a few pairs (CPU, same definition).
    {
      const CascadeProjections projections = GenerateCascadeProjections(cas);
      CascadeStats stats;
      CascadeScratch scratch;
      for (size_t k = 0; k < std::min<size_t>(4, cpu_subset.size()); ++k) {
        const CascadeImage a = BuildCascadeImage(images[cpu_subset[k].first], features, projections, mean);
        const CascadeImage b = BuildCascadeImage(images[cpu_subset[k].second], features, projections, mean);
        CascadeMatchOneWay(a, b, sift, cas, &scratch, &stats);
      }
      row.entries_per_query = double(stats.bucket_entries) / std::max<uint64_t>(1, stats.num_queries);
      row.within_tau_per_query = double(stats.within_tau) / std::max<uint64_t>(1, stats.num_queries);
    }
    {
      auto cpu = CreateCpuFeatureMatcher(sift, cas, mean);
      for (size_t i = 0; i < images.size(); ++i) cpu->AddImage(image_t(i), images[i]);
      const auto start = Clock::now();
      cpu->Match(cpu_subset);
      row.cpu_cascade = cpu_subset.size() / Seconds(start);
    }
    if (gpu) {
      std::vector<FeatureMatches> cascade_subset, tiled_all;
      {
        auto matcher = cashash::cuda::CreateGpuFeatureMatcher(sift, cas, mean, 0);
        for (size_t i = 0; i < images.size(); ++i) matcher->AddImage(image_t(i), images[i]);
        auto start = Clock::now();
        matcher->Match({pairs.front()});  // hashes every image
        row.hash_ms = 1e3 * Seconds(start);
        std::vector<double> rates;
        std::vector<FeatureMatches> all;
        for (int r = 0; r < args.repeats; ++r) {
          start = Clock::now();
          all = matcher->Match(pairs);
          rates.push_back(pairs.size() / Seconds(start));
        }
        std::sort(rates.begin(), rates.end());
        row.gpu_cascade = rates[rates.size() / 2];
        row.matches_per_pair = double(CountMatches(all)) / pairs.size();
        cascade_subset = matcher->Match(bf_subset);
        tiled_all = std::move(all);
      }
      // The same pairs by the other kernels (GpuMatcherConfig::cascade_kernel).
      const auto other_kernel = [&](cashash::cuda::GpuCascadeKernel kernel, double* rate, int* identical) {
        cashash::cuda::GpuMatcherConfig config;
        config.cascade_kernel = kernel;
        auto matcher = cashash::cuda::CreateGpuFeatureMatcher(sift, cas, mean, config);
        for (size_t i = 0; i < images.size(); ++i) matcher->AddImage(image_t(i), images[i]);
        matcher->Match({pairs.front()});
        std::vector<double> rates;
        std::vector<FeatureMatches> other;
        for (int r = 0; r < args.repeats; ++r) {
          const auto start = Clock::now();
          other = matcher->Match(pairs);
          rates.push_back(pairs.size() / Seconds(start));
        }
        std::sort(rates.begin(), rates.end());
        *rate = rates[rates.size() / 2];
        *identical = other == tiled_all ? 1 : 0;
      };
      other_kernel(cashash::cuda::GpuCascadeKernel::kPerQuery, &row.gpu_cascade_direct, &row.direct_identical);
      try {
        CasHashOptions bf_options = cas;
        bf_options.matcher = MatcherType::kBruteForce;
        auto bf = cashash::cuda::CreateGpuFeatureMatcher(sift, bf_options, mean, 0);
        for (size_t i = 0; i < images.size(); ++i) bf->AddImage(image_t(i), images[i]);
        bf->Match({bf_subset.front()});  // warm-up
        const auto start = Clock::now();
        const auto exact = bf->Match(bf_subset);
        row.gpu_bf = bf_subset.size() / Seconds(start);
        row.recall = Recall(cascade_subset, exact);
      } catch (const std::exception& e) {
        std::printf("GPU brute force unavailable: %s\n", e.what());
      }
    }
    std::printf("features %d: %zu pairs, gpu cascade %.0f pairs/s (hash of %d images %.1f ms), gpu bf %.0f pairs/s, "
                "cpu cascade %.1f pairs/s, entries/query %.1f, within tau/query %.1f, matches/pair %.1f, recall %.4f, "
                "per-query kernel %.0f pairs/s (identical matches: %d)\n",
                features, row.pairs, row.gpu_cascade, args.images, row.hash_ms, row.gpu_bf, row.cpu_cascade,
                row.entries_per_query, row.within_tau_per_query, row.matches_per_pair, row.recall,
                row.gpu_cascade_direct, row.direct_identical);
    std::fflush(stdout);
    rows.push_back(row);
  }
  std::printf("\n%8s %8s %14s %14s %12s %12s %9s %9s %11s %8s\n", "features", "pairs", "gpu_cas_pps",
              "per_query_pps", "gpu_bf_pps", "cpu_cas_pps", "entries/q", "in_tau/q", "matches/pr", "recall");
  for (const Row& r : rows) {
    std::printf("%8d %8zu %14.0f %14.0f %12.0f %12.1f %9.1f %9.1f %11.1f %8.4f\n", r.features, r.pairs,
                r.gpu_cascade, r.gpu_cascade_direct, r.gpu_bf, r.cpu_cascade, r.entries_per_query,
                r.within_tau_per_query, r.matches_per_pair, r.recall);
  }
  return 0;
}
