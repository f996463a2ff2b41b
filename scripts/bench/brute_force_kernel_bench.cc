// Times the CPU brute-force kernels on one pair of images with real SIFT
// descriptors: for each kernel the processor runs, the best of --repeats
// timings of BruteForceMatchPair (one thread), wall clock and the thread's
// CPU time (which other jobs on the cores do not inflate), with the
// multiply-adds per CPU second. docs/cpu_matching.md compares them with the
// machine's peak.
//
//   brute_force_kernel_bench DATABASE [IMAGE_ID_A IMAGE_ID_B] [--repeats N]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <ctime>

#include "cashash/matching/brute_force_matcher.h"
#include "colmap_bridge/database.h"

using namespace cashash;

namespace {

double ThreadCpuSeconds() {
  timespec now{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s DATABASE [IMAGE_ID_A IMAGE_ID_B] [--repeats N]\n", argv[0]);
    return 2;
  }
  image_t first = 1, second = 2;
  int repeats = 3;
  int positional = 0;
  for (int i = 2; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--repeats" && i + 1 < argc) {
      repeats = std::max(1, std::atoi(argv[++i]));
    } else if (positional == 0) {
      first = static_cast<image_t>(std::atoi(argv[i]));
      ++positional;
    } else {
      second = static_cast<image_t>(std::atoi(argv[i]));
      ++positional;
    }
  }
  const colmap::Database database(argv[1], /*read_only=*/true);
  const FeatureDescriptors a = database.ReadDescriptors(first);
  const FeatureDescriptors b = database.ReadDescriptors(second);
  const double macs = static_cast<double>(a.rows()) * static_cast<double>(b.rows()) * kDescriptorDim;
  std::printf("images %u and %u: %zu x %zu features, %.2f G multiply-adds a pair\n", first, second, a.rows(),
              b.rows(), macs * 1e-9);
  for (const DotKernel kernel : {DotKernel::kInt16Avx2, DotKernel::kInt8AvxVnni, DotKernel::kInt8Vnni512}) {
    if (!DotKernelAvailable(kernel)) {
      std::printf("%-18s not available on this processor\n", DotKernelName(kernel).c_str());
      continue;
    }
    const WideDescriptors wa = WidenDescriptors(a, a.rows(), kernel);
    const WideDescriptors wb = WidenDescriptors(b, b.rows(), kernel);
    double best = 1e30, best_cpu = 1e30;
    size_t matches = 0;
    for (int r = 0; r < repeats; ++r) {
      const auto start = std::chrono::steady_clock::now();
      const double cpu_start = ThreadCpuSeconds();
      matches = BruteForceMatchPair(wa, wb, SiftMatchingOptions()).size();
      best_cpu = std::min(best_cpu, ThreadCpuSeconds() - cpu_start);
      best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    }
    std::printf("%-18s %8.1f ms a pair (%.1f ms CPU), %6.1f G multiply-adds per CPU second, %zu matches\n",
                DotKernelName(kernel).c_str(), 1e3 * best, 1e3 * best_cpu, macs / best_cpu * 1e-9, matches);
  }
  return 0;
}
