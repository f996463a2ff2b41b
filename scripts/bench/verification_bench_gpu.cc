// Geometric verification of the same matches by the CPU batch verifier (all
// cores) and the GPU one (F, H and E on the device, the decision on the CPU),
// printed as a table. Pairs come from a verification pairs file
// (scripts/bench/dump_verification_pairs) or, without one, from synthetic
// scenes; --replicate K verifies every pair K times under different seeds, to
// give the GPU a full chunk's worth of pairs.
//
// Usage: verification_bench_gpu [--pairs FILE] [--replicate K] [--repeats R]
//                               [--threads T] [--no-priors] [--cpu-max-pairs N]
//                               [--gpu-only]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "../../tests/support/synthetic_two_view.h"
#include "cashash/pipeline/batch_verifier.h"
#include "cashash/base/pair_id.h"
#include "cashash/base/parallel_for.h"
#include "cashash/pipeline/verification_pairs_file.h"
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#include "cashash_cuda/geometry/two_view_geometry.h"

namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::vector<cashash::StoredVerificationPair> SyntheticPairs() {
  std::vector<cashash::StoredVerificationPair> pairs;
  for (int k = 0; k < 60; ++k) {
    cashash::testing_support::SceneOptions o;
    o.seed = static_cast<unsigned>(k + 1);
    o.num_inliers = 300 + 60 * (k % 20);
    o.outlier_ratio = 0.1 + 0.1 * (k % 8);
    o.planar = k % 7 == 3;
    const cashash::testing_support::SyntheticScene s = cashash::testing_support::MakeScene(o);
    cashash::StoredVerificationPair p;
    p.pair = {1, static_cast<cashash::image_t>(k + 2)};
    p.camera1 = p.camera2 = s.MakeCamera(k % 2 == 0);
    p.points1 = s.points1;
    p.points2 = s.points2;
    p.matches = s.matches;
    pairs.push_back(std::move(p));
  }
  return pairs;
}

struct Agreement {
  int same_config = 0, verified = 0, close_inliers = 0;
};

Agreement Compare(const std::vector<cashash::TwoViewGeometry>& cpu, const std::vector<cashash::TwoViewGeometry>& gpu) {
  Agreement a;
  for (size_t k = 0; k < cpu.size(); ++k) {
    a.same_config += cpu[k].config == gpu[k].config;
    if (cpu[k].config >= cashash::kCalibrated && cpu[k].config == gpu[k].config) {
      ++a.verified;
      const double c = static_cast<double>(cpu[k].inlier_matches.size());
      const double g = static_cast<double>(gpu[k].inlier_matches.size());
      a.close_inliers += std::abs(c - g) <= std::max(5.0, 0.05 * c);
    }
  }
  return a;
}

}  // namespace

int main(int argc, char** argv) {
  std::string pairs_path;
  int replicate = 1, repeats = 3, threads = -1;
  size_t cpu_max_pairs = 0;
  bool no_priors = false;
  bool gpu_only = false;  // time the GPU alone (CPU columns read 0)
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s needs a value\n", arg.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (arg == "--pairs") pairs_path = next();
    else if (arg == "--replicate") replicate = std::max(1, std::atoi(next()));
    else if (arg == "--repeats") repeats = std::max(1, std::atoi(next()));
    else if (arg == "--threads") threads = std::atoi(next());
    else if (arg == "--cpu-max-pairs") cpu_max_pairs = std::strtoull(next(), nullptr, 10);
    else if (arg == "--no-priors") no_priors = true;
    else if (arg == "--gpu-only") gpu_only = true;
    else {
      std::fprintf(stderr,
                   "usage: %s [--pairs FILE] [--replicate K] [--repeats R] [--threads T] [--no-priors] "
                   "[--cpu-max-pairs N] [--gpu-only]\n",
                   argv[0]);
      return 2;
    }
  }
  std::string reason;
  if (cashash::cuda::NumCudaDevices() == 0 || !cashash::cuda::CudaDeviceUsable(0, &reason)) {
    std::printf("no usable CUDA device (%s); nothing to compare\n", reason.c_str());
    return 0;
  }
  std::vector<cashash::StoredVerificationPair> stored =
      pairs_path.empty() ? SyntheticPairs() : cashash::ReadVerificationPairsFile(pairs_path);
  if (no_priors) {
    for (auto& p : stored) p.camera1.has_prior_focal_length = p.camera2.has_prior_focal_length = false;
  }
  std::vector<cashash::VerificationPair> pairs;
  size_t matches = 0, calibrated = 0;
  for (int r = 0; r < replicate; ++r) {
    for (const auto& p : stored) {
      pairs.push_back(p.View(cashash::PairRandomSeed(static_cast<uint64_t>(r), p.pair)));
      matches += p.matches.size();
      calibrated += cashash::TwoViewIsCalibrated(p.camera1, p.camera2);
    }
  }
  const int num_threads = cashash::ResolveNumThreads(threads);
  std::printf("%zu pairs (%zu stored x %d), %zu matches, %zu calibrated pairs (E estimated), %d CPU threads\n",
              pairs.size(), stored.size(), replicate, matches, calibrated, num_threads);

  const cashash::TwoViewGeometryOptions options;
  auto cpu = cashash::CreateCpuBatchVerifier(options, threads);
  auto gpu = cashash::cuda::CreateGpuBatchVerifier(options, 0, threads);
  // Every hypothesis scored in full (TwoViewGeometry.sprt 0): what the
  // sequential test saves, and whether it keeps the decisions.
  cashash::TwoViewGeometryOptions full_scan = options;
  full_scan.sprt = false;
  auto gpu_full_scan = cashash::cuda::CreateGpuBatchVerifier(full_scan, 0, threads);
  // The CPU may verify a subset only (it is slow); its time is scaled up.
  std::vector<cashash::VerificationPair> cpu_pairs = pairs;
  if (cpu_max_pairs > 0 && cpu_pairs.size() > cpu_max_pairs) cpu_pairs.resize(cpu_max_pairs);
  const double cpu_scale = static_cast<double>(pairs.size()) / static_cast<double>(cpu_pairs.size());

  gpu->Verify(std::vector<cashash::VerificationPair>(pairs.begin(), pairs.begin() + std::min<size_t>(pairs.size(), 8)));
  std::vector<cashash::TwoViewGeometry> cpu_result, gpu_result, gpu_full_scan_result;
  double cpu_best = gpu_only ? 0 : 1e30, gpu_best = 1e30, gpu_full_scan_best = 1e30;
  for (int r = 0; r < repeats; ++r) {
    auto t0 = Clock::now();
    if (!gpu_only) {
      cpu_result = cpu->Verify(cpu_pairs);
      cpu_best = std::min(cpu_best, Seconds(t0) * cpu_scale);
    }
    t0 = Clock::now();
    gpu_result = gpu->Verify(pairs);
    gpu_best = std::min(gpu_best, Seconds(t0));
    t0 = Clock::now();
    gpu_full_scan_result = gpu_full_scan->Verify(pairs);
    gpu_full_scan_best = std::min(gpu_full_scan_best, Seconds(t0));
  }
  // The GPU's F and H alone (no E, no decision), and E alone on the CPU.
  std::vector<cashash::TwoViewPoints> points(pairs.size());
  auto t_prepare = Clock::now();
  cashash::ParallelFor(pairs.size(), threads, [&](size_t k) {
    points[k] = cashash::PrepareTwoViewPoints(*pairs[k].points1, *pairs[k].points2, *pairs[k].matches);
  });
  const double prepare_seconds = Seconds(t_prepare);
  std::vector<const cashash::TwoViewPoints*> pointers;
  std::vector<uint64_t> seeds;
  for (size_t k = 0; k < pairs.size(); ++k) {
    pointers.push_back(&points[k]);
    seeds.push_back(pairs[k].random_seed);
  }
  cashash::cuda::GpuTwoViewRansac ransac(options, 0);
  std::vector<cashash::TwoViewModelEstimate> F, H;
  ransac.Estimate(pointers, seeds, &F, &H);  // sizes the buffers
  auto t0 = Clock::now();
  ransac.Estimate(pointers, seeds, &F, &H);
  const double gpu_fh = Seconds(t0);
  const cashash::cuda::GpuRansacStats fh_stats = ransac.stats();
  // F, H and E of the calibrated pairs (E's points prepared beforehand).
  std::vector<cashash::EssentialPoints> essential(pairs.size());
  std::vector<const cashash::EssentialPoints*> essential_pointers(pairs.size(), nullptr);
  cashash::ParallelFor(pairs.size(), threads, [&](size_t k) {
    if (!cashash::TwoViewIsCalibrated(*pairs[k].camera1, *pairs[k].camera2)) return;
    essential[k] = cashash::PrepareEssentialPoints(*pairs[k].camera1, *pairs[k].camera2, points[k].pixels, options);
    essential_pointers[k] = &essential[k];
  });
  std::vector<cashash::TwoViewModelEstimate> E;
  // Once untimed, as for F and H: the first call with E grows its buffers and
  // loads its kernel, about 0.1 s that would otherwise count as E's.
  ransac.Estimate(pointers, seeds, essential_pointers, &F, &H, &E);
  const cashash::cuda::GpuRansacStats before_fhe = ransac.stats();  // the stats add up over calls
  t0 = Clock::now();
  ransac.Estimate(pointers, seeds, essential_pointers, &F, &H, &E);
  const double gpu_fhe = Seconds(t0);
  t0 = Clock::now();
  cashash::ParallelFor(gpu_only ? 0 : cpu_pairs.size(), threads, [&](size_t k) {
    cashash::TwoViewGeometryOptions o = options;
    o.random_seed = cpu_pairs[k].random_seed;
    cashash::EstimateFundamental(points[k], o);
    cashash::EstimateHomography(points[k], o);
  });
  const double cpu_fh = Seconds(t0) * cpu_scale;
  t0 = Clock::now();
  cashash::ParallelFor(gpu_only ? 0 : cpu_pairs.size(), threads, [&](size_t k) {
    if (!cashash::TwoViewIsCalibrated(*cpu_pairs[k].camera1, *cpu_pairs[k].camera2)) return;
    cashash::TwoViewGeometryOptions o = options;
    o.random_seed = cpu_pairs[k].random_seed;
    // Stopped as the GPU's E is, from the counts of F and H.
    cashash::EstimateEssential(
        *cpu_pairs[k].camera1, *cpu_pairs[k].camera2, points[k].pixels, o,
        cashash::TwoViewEssentialSettledInliers(F[k].success ? F[k].num_inliers : 0, H[k].success ? H[k].num_inliers : 0,
                                            static_cast<int>(points[k].pixels.size()), o));
  });
  const double cpu_e = Seconds(t0) * cpu_scale;
  // The decision (with the watermark test) from the GPU's F and H, no E.
  t0 = Clock::now();
  cashash::ParallelFor(pairs.size(), threads, [&](size_t k) {
    cashash::DecideTwoViewGeometry(*pairs[k].camera1, *pairs[k].camera2, points[k].pixels, *pairs[k].matches,
                                   false, F[k], H[k], cashash::TwoViewModelEstimate(), options);
  });
  const double decide_seconds = Seconds(t0);
  const cashash::cuda::GpuRansacStats& st = fh_stats;
  cashash::cuda::GpuRansacStats all = ransac.stats();  // E's of the timed call alone
  all.pairs_E -= before_fhe.pairs_E;
  all.trials_E -= before_fhe.trials_E;
  all.local_refits_E -= before_fhe.local_refits_E;

  std::vector<cashash::TwoViewGeometry> gpu_subset(gpu_result.begin(), gpu_result.begin() + cpu_result.size());
  const Agreement a = Compare(cpu_result, gpu_subset);
  std::printf("\n| step | CPU (%d threads) s | GPU s | speed-up | GPU pairs/s |\n|---|---|---|---|---|\n", num_threads);
  std::printf("| whole verification (F, H, E, decision) | %.3f | %.3f | %.1fx | %.0f |\n", cpu_best, gpu_best,
              cpu_best / gpu_best, pairs.size() / gpu_best);
  std::printf("| whole verification, every hypothesis scored in full (TwoViewGeometry.sprt 0) | - | %.3f | - | %.0f |\n",
              gpu_full_scan_best, pairs.size() / gpu_full_scan_best);
  std::printf("| F and H only | %.3f | %.3f | %.1fx | %.0f |\n", cpu_fh, gpu_fh, cpu_fh / gpu_fh,
              pairs.size() / gpu_fh);
  if (calibrated > 0) {
    std::printf("| F, H and E (E of the %zu calibrated pairs) | %.3f | %.3f | %.1fx | %.0f |\n", calibrated,
                cpu_fh + cpu_e, gpu_fhe, (cpu_fh + cpu_e) / gpu_fhe, pairs.size() / gpu_fhe);
  }
  std::printf("| E only (calibrated pairs; GPU: F, H and E less F and H) | %.3f | %.3f | - | - |\n", cpu_e,
              gpu_fhe - gpu_fh);
  std::printf("| preparing points (CPU in both) | - | %.3f | - | - |\n", prepare_seconds);
  std::printf("| decision and watermark test (CPU in both) | - | %.3f | - | - |\n", decide_seconds);
  std::printf("\nGPU F/H (two calls): %.3f s on the device (upload + kernels + download), mean trials F %.0f H %.0f, "
              "local refits per pair F %.1f H %.1f\n",
              st.seconds_gpu, static_cast<double>(st.trials_F) / st.pairs, static_cast<double>(st.trials_H) / st.pairs,
              static_cast<double>(st.local_refits_F) / st.pairs, static_cast<double>(st.local_refits_H) / st.pairs);
  if (all.pairs_E > 0) {
    std::printf("GPU E: mean trials %.0f, local refits per pair %.1f (%zu pairs)\n",
                static_cast<double>(all.trials_E) / all.pairs_E, static_cast<double>(all.local_refits_E) / all.pairs_E,
                all.pairs_E);
    // Where E's device time goes: pairs by E rounds (256 trials each), and
    // F, H and E again without the pairs of more than 4 rounds, the same
    // seeds (so the same trials): what those few pairs cost the launch.
    const int edges[] = {1, 4, 16, 40, 1 << 20};
    size_t count[5] = {}, matches_in[5] = {};
    std::vector<const cashash::TwoViewPoints*> short_points;
    std::vector<const cashash::EssentialPoints*> short_essential;
    std::vector<uint64_t> short_seeds;
    for (size_t k = 0; k < pairs.size(); ++k) {
      if (essential_pointers[k] == nullptr) continue;
      const int rounds = (E[k].num_trials + 255) / 256;
      int b = 0;
      while (rounds > edges[b]) ++b;
      ++count[b];
      matches_in[b] += pairs[k].matches->size();
      if (rounds <= 4) {
        short_points.push_back(pointers[k]);
        short_essential.push_back(essential_pointers[k]);
        short_seeds.push_back(seeds[k]);
      }
    }
    std::printf("E rounds per pair (<= 1, 2-4, 5-16, 17-40, more): pairs");
    for (size_t c : count) std::printf(" %zu", c);
    std::printf("; mean matches");
    for (int b = 0; b < 5; ++b) std::printf(" %.0f", count[b] ? static_cast<double>(matches_in[b]) / count[b] : 0.0);
    std::vector<cashash::TwoViewModelEstimate> F2, H2, E2;
    t0 = Clock::now();
    ransac.Estimate(short_points, short_seeds, short_essential, &F2, &H2, &E2);
    std::printf("\nF, H and E without the pairs of more than 4 E rounds (%zu of %zu pairs): %.3f s (all: %.3f s)\n",
                short_points.size(), pairs.size(), Seconds(t0), gpu_fhe);
    // The launch order: the same pairs (same seeds, so the same work) with
    // the longest E first, by this call's trials, and with the fewest
    // matches first, an order known before the call (the pairs that run to
    // the trial cap are small ones). Far below "as given", the grid's tail
    // is where E's time goes.
    const auto time_in_order = [&](const std::vector<size_t>& order) {
      std::vector<const cashash::TwoViewPoints*> p;
      std::vector<const cashash::EssentialPoints*> e;
      std::vector<uint64_t> sd;
      for (const size_t k : order) {
        p.push_back(pointers[k]);
        e.push_back(essential_pointers[k]);
        sd.push_back(seeds[k]);
      }
      std::vector<cashash::TwoViewModelEstimate> F3, H3, E3;
      const auto start = Clock::now();
      ransac.Estimate(p, sd, e, &F3, &H3, &E3);
      return Seconds(start);
    };
    std::vector<size_t> order(pairs.size());
    for (size_t k = 0; k < order.size(); ++k) order[k] = k;
    const double as_given = time_in_order(order);
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return E[a].num_trials > E[b].num_trials; });
    const double longest_first = time_in_order(order);
    std::stable_sort(order.begin(), order.end(),
                     [&](size_t a, size_t b) { return pairs[a].matches->size() < pairs[b].matches->size(); });
    const double fewest_matches_first = time_in_order(order);
    std::printf("F, H and E by launch order: as given %.3f s, longest E first %.3f s, fewest matches first %.3f s\n",
                as_given, longest_first, fewest_matches_first);
  }
  const Agreement full = Compare(gpu_full_scan_result, gpu_result);
  auto totals = [](const std::vector<cashash::TwoViewGeometry>& r, size_t* verified, size_t* inliers) {
    *verified = *inliers = 0;
    for (const cashash::TwoViewGeometry& g : r) {
      if (g.config < cashash::kCalibrated) continue;
      ++*verified;
      *inliers += g.inlier_matches.size();
    }
  };
  size_t verified_on, inliers_on, verified_off, inliers_off;
  totals(gpu_result, &verified_on, &inliers_on);
  totals(gpu_full_scan_result, &verified_off, &inliers_off);
  std::printf("sequential test against the full scan on %zu pairs: same config %d, verified with inlier counts "
              "within 5%%: %d/%d; verified pairs %zu against %zu, inlier matches %zu against %zu\n",
              pairs.size(), full.same_config, full.close_inliers, full.verified, verified_on, verified_off,
              inliers_on, inliers_off);
  std::printf("agreement on %zu pairs: same config %d, verified with inlier counts within 5%%: %d/%d%s\n",
              cpu_result.size(), a.same_config, a.close_inliers, a.verified,
              cpu_scale > 1 ? " (CPU ran a subset; its times are scaled up)" : "");
  return 0;
}
