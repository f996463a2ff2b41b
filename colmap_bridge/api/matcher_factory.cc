// CreateMatcherForRun (declared in matching_api.h, the public API): which
// FeatureMatcher a run builds from its resolved options and devices.
#include "colmap_bridge/api/matching_api.h"

#include <algorithm>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "cashash/matchers/exact_rematch_feature_matcher.h"
#include "cashash/matchers/fallback_feature_matcher.h"
#include "cashash/matchers/split_feature_matcher.h"
#include "cashash/matching/table_shape.h"
#ifdef CASHASH_WITH_CUDA
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#endif

namespace cashash {
namespace colmap {

namespace {

// The backend of one matcher type (cascade or brute force): one per device
// of the run (ResolvedRun::gpu_indices, each inside a fallback to the CPU on
// device-memory errors; several under a SplitFeatureMatcher), else the CPU.
std::unique_ptr<FeatureMatcher> CreateBackendForOptions(const MatcherCommandOptions& options,
                                                        const std::vector<int>& gpu_indices,
                                                        size_t gpu_memory_budget_bytes, const MeanDescriptor& mean,
                                                        const std::function<void(const std::string&)>& warning) {
#ifdef CASHASH_WITH_CUDA
  std::vector<std::unique_ptr<FeatureMatcher>> parts;
  for (const int gpu_index : gpu_indices) {
    cuda::GpuMatcherConfig config;
    config.gpu_index = gpu_index;
    config.memory_budget_bytes = gpu_memory_budget_bytes;
    // A run that outgrows the card (device memory) finishes on the CPU.
    parts.push_back(CreateFallbackFeatureMatcher(
        cuda::CreateGpuFeatureMatcher(options.sift, options.cashash, mean, config),
        [sift = options.sift, cashash = options.cashash, mean]() {
          return CreateCpuFeatureMatcher(sift, cashash, mean);
        },
        IsDeviceMemoryError, warning));
  }
  if (parts.size() == 1) return std::move(parts[0]);
  // Several devices share every chunk of pairs.
  if (!parts.empty()) return std::make_unique<SplitFeatureMatcher>(std::move(parts));
#else
  (void)gpu_indices;
  (void)gpu_memory_budget_bytes;
  (void)warning;
#endif
  return CreateCpuFeatureMatcher(options.sift, options.cashash, mean);
}

// Brute-force matchers on the run's GPU for the exact rematch deferred to the
// verification threads (exact_rematch_feature_matcher.h); null where it
// stays on the matching thread: with several GPUs (each chunk is split
// between them), or where the run placed it there
// (ResolvedRun::rematch_on_matching_thread).
std::shared_ptr<ExactMatcherPool> DeferredRematchPool(const ResolvedRun& run, const MeanDescriptor& mean) {
#ifdef CASHASH_WITH_CUDA
  if (run.rematch_on_matching_thread) return nullptr;
  if (run.gpu_indices.size() != 1) return nullptr;
  MatcherCommandOptions brute_force = run.options;
  brute_force.cashash.matcher = MatcherType::kBruteForce;
  return std::make_shared<ExactMatcherPool>(
      [brute_force, devices = run.gpu_indices, budget = run.gpu_memory_budget_bytes, mean]() {
        return CreateBackendForOptions(brute_force, devices, budget, mean, nullptr);
      });
#else
  (void)run;
  (void)mean;
  return nullptr;
#endif
}

// The cascade backend of a run; with --CasHash.exact_rematch_min_matches > 0
// it also matches the pairs that may verify again exactly, from the
// descriptors it holds (exact_rematch_feature_matcher.h). Guided matching
// keeps the bare cascade: its stage 2 screens by the epipolar band.
std::unique_ptr<FeatureMatcher> CreateCascadeForRun(const ResolvedRun& run, const MeanDescriptor& mean,
                                                    const std::function<void(const std::string&)>& warning,
                                                    const std::shared_ptr<ExactRematchCounts>& counts) {
  const MatcherCommandOptions& options = run.options;
  MatcherCommandOptions cascade = options;
  cascade.cashash.matcher = MatcherType::kCascade;
  std::unique_ptr<FeatureMatcher> matcher =
      CreateBackendForOptions(cascade, run.gpu_indices, run.gpu_memory_budget_bytes, mean, warning);
  if (options.guided.enabled || options.cashash.exact_rematch_min_matches <= 0) return matcher;
  return std::make_unique<ExactRematchFeatureMatcher>(
      std::move(matcher), static_cast<size_t>(options.cashash.exact_rematch_min_matches), counts,
      DeferredRematchPool(run, mean),
      static_cast<size_t>(std::max(0, options.cashash.exact_rematch_max_matches)));
}

}  // namespace

std::unique_ptr<FeatureMatcher> CreateMatcherForRun(const ResolvedRun& run, const MeanDescriptor& mean,
                                                    const std::function<void(const std::string&)>& warning,
                                                    const std::shared_ptr<ExactRematchCounts>& counts) {
  const MatcherCommandOptions& options = run.options;
  // ResolveRun decides auto (MatcherRule); a ResolvedRun is built by it only.
  if (options.cashash.matcher == MatcherType::kAuto) {
    throw std::logic_error("CreateMatcherForRun: CasHash.matcher auto was not resolved (ResolveRun decides it)");
  }
  if (options.cashash.matcher == MatcherType::kCascade) return CreateCascadeForRun(run, mean, warning, counts);
  return CreateBackendForOptions(options, run.gpu_indices, run.gpu_memory_budget_bytes, mean, warning);
}

}  // namespace colmap
}  // namespace cashash
