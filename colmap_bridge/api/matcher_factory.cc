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
#include "colmap_bridge/api/run_gpu_resources.h"
#ifdef CASHASH_WITH_CUDA
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#endif

namespace cashash {
namespace colmap {

namespace {

// The backend of one matcher type (cascade or brute force): one per device
// of the run (ResolvedRun::gpu_indices, each inside a fallback to the CPU on
// device-memory errors; several under a SplitFeatureMatcher), else the CPU.
// `gpu` (may be null: each GPU matcher then owns its memory) gives each
// device's owner of memory.
std::unique_ptr<FeatureMatcher> CreateBackendForOptions(const MatcherCommandOptions& options,
                                                        const std::vector<int>& gpu_indices,
                                                        size_t gpu_memory_budget_bytes, const MeanDescriptor& mean,
                                                        const std::function<void(const std::string&)>& warning,
                                                        RunGpuResources* gpu) {
#ifdef CASHASH_WITH_CUDA
  std::vector<std::unique_ptr<FeatureMatcher>> parts;
  for (const int gpu_index : gpu_indices) {
    cuda::GpuMatcherConfig config;
    config.gpu_index = gpu_index;
    config.memory_budget_bytes = gpu_memory_budget_bytes;
    if (gpu != nullptr) config.resources = gpu->ForDevice(gpu_index);
    // A run that outgrows the card (device memory) finishes on the CPU.
    parts.push_back(CreateFallbackFeatureMatcher(
        cuda::CreateGpuFeatureMatcher(options.sift, options.cashash, mean, config),
        [sift = options.sift, cashash = options.cashash, mean]() {
          return CreateCpuFeatureMatcher(sift, cashash, mean);
        },
        IsDeviceMemoryError, [warning, gpu](const std::string& text) {
          if (gpu != nullptr) gpu->NoteMatcherFallback();
          if (warning) warning(text);
        }));
  }
  if (parts.size() == 1) return std::move(parts[0]);
  // Several devices share every chunk of pairs.
  if (!parts.empty()) return std::make_unique<SplitFeatureMatcher>(std::move(parts));
#else
  (void)gpu_indices;
  (void)gpu_memory_budget_bytes;
  (void)warning;
  (void)gpu;
#endif
  return CreateCpuFeatureMatcher(options.sift, options.cashash, mean);
}

// Brute-force matchers on the run's GPU for the exact rematch deferred to the
// verification threads (exact_rematch_feature_matcher.h); null where it
// stays on the matching thread: with several GPUs (each chunk is split
// between them), or where the run placed it there
// (ResolvedRun::rematch_on_matching_thread).
std::shared_ptr<ExactMatcherPool> DeferredRematchPool(const ResolvedRun& run, const MeanDescriptor& mean,
                                                      RunGpuResources* gpu) {
#ifdef CASHASH_WITH_CUDA
  if (run.rematch_on_matching_thread) return nullptr;
  if (run.gpu_indices.size() != 1) return nullptr;
  MatcherCommandOptions brute_force = run.options;
  brute_force.cashash.matcher = MatcherType::kBruteForce;
  return std::make_shared<ExactMatcherPool>(
      [brute_force, devices = run.gpu_indices, budget = run.gpu_memory_budget_bytes, mean, gpu]() {
        return CreateBackendForOptions(brute_force, devices, budget, mean, nullptr, gpu);
      });
#else
  (void)run;
  (void)mean;
  (void)gpu;
  return nullptr;
#endif
}

// The cascade backend of a run; with --CasHash.exact_rematch_min_matches > 0
// it also matches the pairs that may verify again exactly, from the
// descriptors it holds (exact_rematch_feature_matcher.h). Guided matching
// keeps the bare cascade: its stage 2 screens by the epipolar band.
std::unique_ptr<FeatureMatcher> CreateCascadeForRun(const ResolvedRun& run, const MeanDescriptor& mean,
                                                    const std::function<void(const std::string&)>& warning,
                                                    const std::shared_ptr<ExactRematchCounts>& counts,
                                                    RunGpuResources* gpu) {
  const MatcherCommandOptions& options = run.options;
  MatcherCommandOptions cascade = options;
  cascade.cashash.matcher = MatcherType::kCascade;
  std::unique_ptr<FeatureMatcher> matcher =
      CreateBackendForOptions(cascade, run.gpu_indices, run.gpu_memory_budget_bytes, mean, warning, gpu);
  if (options.guided.enabled || options.cashash.exact_rematch_min_matches <= 0) return matcher;
  return std::make_unique<ExactRematchFeatureMatcher>(
      std::move(matcher), static_cast<size_t>(options.cashash.exact_rematch_min_matches), counts,
      DeferredRematchPool(run, mean, gpu),
      static_cast<size_t>(std::max(0, options.cashash.exact_rematch_max_matches)));
}

}  // namespace

std::unique_ptr<FeatureMatcher> CreateMatcherForRun(const ResolvedRun& run, const MeanDescriptor& mean,
                                                    const std::function<void(const std::string&)>& warning,
                                                    const std::shared_ptr<ExactRematchCounts>& counts,
                                                    RunGpuResources* gpu) {
  const MatcherCommandOptions& options = run.options;
  // ResolveRun decides auto (MatcherRule); a ResolvedRun is built by it only.
  if (options.cashash.matcher == MatcherType::kAuto) {
    throw std::logic_error("CreateMatcherForRun: CasHash.matcher auto was not resolved (ResolveRun decides it)");
  }
  if (options.cashash.matcher == MatcherType::kCascade) return CreateCascadeForRun(run, mean, warning, counts, gpu);
  return CreateBackendForOptions(options, run.gpu_indices, run.gpu_memory_budget_bytes, mean, warning, gpu);
}

}  // namespace colmap
}  // namespace cashash
