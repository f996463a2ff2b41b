// Verifies every pair of a verification pairs file twice on the CPU, with
// COLMAP's full trial budget (every hypothesis scored in full) and with the
// early exit of RANSAC (--TwoViewGeometry.early_exit) and, unless --sprt 0,
// the sequential test of hypotheses (--TwoViewGeometry.sprt), and reports
// how often the decision (the configuration) is the same, how many model
// estimations stopped early and the time of each run.
//
//   early_exit_agreement PAIRS.bin [--threads T] [--max_risk R] [--sprt 0|1]
//                        [--min_agreement A] [--min_stopped S]
//
// Exits 1 when the share of pairs with the same configuration is below A
// (default 0.995), or when fewer than S pairs' F estimations stopped early
// (default 0), so that the integration test can use it as a check.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include "cashash/pipeline/batch_verifier.h"
#include "cashash/base/parallel_for.h"
#include "cashash/geometry/two_view_geometry.h"
#include "cashash/pipeline/verification_pairs_file.h"

namespace {

using namespace cashash;
using Clock = std::chrono::steady_clock;

struct Run {
  std::vector<TwoViewGeometry> geometries;
  double seconds = 0;
};

Run VerifyAll(const std::vector<StoredVerificationPair>& pairs, const TwoViewGeometryOptions& options, int threads) {
  Run run;
  run.geometries.resize(pairs.size());
  const Clock::time_point start = Clock::now();
  ParallelFor(pairs.size(), threads, [&](size_t k) {
    TwoViewGeometryOptions o = options;
    o.random_seed = PairRandomSeed(options.random_seed, pairs[k].pair);
    run.geometries[k] = EstimateTwoViewGeometry(pairs[k].camera1, pairs[k].points1, pairs[k].camera2,
                                                pairs[k].points2, pairs[k].matches, o);
  });
  run.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return run;
}

bool Verified(const TwoViewGeometry& g) { return g.config >= kCalibrated; }

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: " << argv[0] << " PAIRS.bin [--threads T] [--max_risk R] [--sprt 0|1] [--min_agreement A]\n";
    return 2;
  }
  int threads = -1;
  double min_agreement = 0.995;
  size_t min_stopped = 0;
  TwoViewGeometryOptions early;
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--threads") threads = std::atoi(argv[i + 1]);
    else if (flag == "--max_risk") early.early_exit_max_risk = std::atof(argv[i + 1]);
    else if (flag == "--sprt") early.sprt = std::atoi(argv[i + 1]) != 0;
    else if (flag == "--min_agreement") min_agreement = std::atof(argv[i + 1]);
    else if (flag == "--min_stopped") min_stopped = std::strtoull(argv[i + 1], nullptr, 10);
    else {
      std::cerr << "unknown option " << flag << "\n";
      return 2;
    }
  }
  try {
    const std::vector<StoredVerificationPair> pairs = ReadVerificationPairsFile(argv[1]);
    TwoViewGeometryOptions full = early;
    full.early_exit = false;
    full.sprt = false;
    early.early_exit = true;
    const Run reference = VerifyAll(pairs, full, threads);
    const Run fast = VerifyAll(pairs, early, threads);
    size_t same_config = 0, same_verified = 0, ransac_pairs = 0, verified_full = 0, verified_early = 0;
    size_t inliers_full = 0, inliers_early = 0;
    for (size_t k = 0; k < pairs.size(); ++k) {
      const TwoViewGeometry& a = reference.geometries[k];
      const TwoViewGeometry& b = fast.geometries[k];
      same_config += a.config == b.config;
      same_verified += Verified(a) == Verified(b);
      ransac_pairs += !TooFewMatchesForTwoView(pairs[k].matches.size(), full);
      verified_full += Verified(a);
      verified_early += Verified(b);
      if (Verified(a)) inliers_full += a.inlier_matches.size();
      if (Verified(b)) inliers_early += b.inlier_matches.size();
      if (a.config != b.config) {
        std::printf("pair %u-%u (%zu matches): full budget config %d with %zu inliers, early exit config %d with %zu\n",
                    pairs[k].pair.first, pairs[k].pair.second, pairs[k].matches.size(), a.config,
                    a.inlier_matches.size(), b.config, b.inlier_matches.size());
      }
    }
    // How many F estimations the chance test stopped (F is the model every
    // pair estimates).
    std::vector<char> stopped(pairs.size(), 0);
    ParallelFor(pairs.size(), threads, [&](size_t k) {
      if (TooFewMatchesForTwoView(pairs[k].matches.size(), early)) return;
      TwoViewGeometryOptions o = early;
      o.random_seed = PairRandomSeed(early.random_seed, pairs[k].pair);
      stopped[k] = EstimateFundamental(PrepareTwoViewPoints(pairs[k].points1, pairs[k].points2, pairs[k].matches), o)
                       .early_exit;
    });
    size_t num_stopped = 0;
    for (char s : stopped) num_stopped += s;
    const double n = pairs.empty() ? 1.0 : static_cast<double>(pairs.size());
    const double agreement = same_config / n;
    std::printf("\n| run | seconds | verified pairs | inlier matches |\n|---|---:|---:|---:|\n");
    std::printf("| full budget | %.3f | %zu | %zu |\n", reference.seconds, verified_full, inliers_full);
    std::printf("| early exit (max_risk %g)%s | %.3f | %zu | %zu |\n", early.early_exit_max_risk,
                early.sprt ? " and the sequential test" : "", fast.seconds, verified_early, inliers_early);
    std::printf("\n%zu pairs (%zu with at least min_num_inliers matches): same configuration %.4f, "
                "same verified/not %.4f, speed-up %.2fx\n",
                pairs.size(), ransac_pairs, agreement, same_verified / n,
                fast.seconds > 0 ? reference.seconds / fast.seconds : 0.0);
    std::printf("F estimations stopped early as chance: %zu of %zu pairs\n", num_stopped, ransac_pairs);
    if (agreement < min_agreement) {
      std::printf("FAILED: agreement %.4f below %.4f\n", agreement, min_agreement);
      return 1;
    }
    if (num_stopped < min_stopped) {
      std::printf("FAILED: %zu F estimations stopped early, expected at least %zu\n", num_stopped, min_stopped);
      return 1;
    }
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "ERROR: " << e.what() << "\n";
    return 1;
  }
}
