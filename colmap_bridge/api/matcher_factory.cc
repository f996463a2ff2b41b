// CreateMatcherForRun and CreateRematchForRun (declared in matching_api.h,
// the public API): which backend and which exact rematch a run builds from
// its resolved options and devices.
#include "colmap_bridge/api/matching_api.h"

#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "cashash/matchers/fallback_feature_matcher.h"
#include "cashash/matchers/split_feature_matcher.h"
#include "colmap_bridge/api/run_gpu_resources.h"
#ifdef CASHASH_WITH_CUDA
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#endif

namespace cashash {
namespace colmap {

namespace {

// The backend of one matcher type (cascade or brute force) on the given
// devices: one per device (each inside a fallback to the CPU on
// device-memory errors; several under a SplitFeatureMatcher), else the CPU.
// `gpu` (may be null: each GPU matcher then owns its memory) gives each
// device's owner of memory.
std::unique_ptr<MatchingBackend> CreateBackendForOptions(const MatcherCommandOptions& options,
                                                         const std::vector<int>& gpu_indices,
                                                         size_t gpu_memory_budget_bytes, const MeanDescriptor& mean,
                                                         const std::function<void(const std::string&)>& warning,
                                                         RunGpuResources* gpu) {
#ifdef CASHASH_WITH_CUDA
  std::vector<std::unique_ptr<MatchingBackend>> parts;
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

}  // namespace

std::unique_ptr<MatchingBackend> CreateMatcherForRun(const ResolvedRun& run, const MeanDescriptor& mean,
                                                     const std::function<void(const std::string&)>& warning,
                                                     RunGpuResources* gpu) {
  // ResolveRun decides every value chosen for the run (auto by MatcherRule,
  // tau, the rematch threshold); a ResolvedRun is built by it only.
  const std::string undecided = run.options.cashash.CheckDecided();
  if (!undecided.empty()) throw std::logic_error("CreateMatcherForRun: not resolved: " + undecided);
  return CreateBackendForOptions(run.options, run.gpu_indices, run.gpu_memory_budget_bytes, mean, warning, gpu);
}

std::unique_ptr<ExactRematchStage> CreateRematchForRun(const ResolvedRun& run, const MeanDescriptor& mean,
                                                       MatchingBackend* backend, RunGpuResources* gpu) {
  std::shared_ptr<ExactMatcherPool> pool;
  if (run.rematch.where == RematchPlace::kVerificationThread) {
    // Brute force on the run's devices, for held images that find no room
    // there: their own fallback goes on on the CPU.
    MatcherCommandOptions brute_force = run.options;
    brute_force.cashash.matcher = MatcherType::kBruteForce;
    pool = std::make_shared<ExactMatcherPool>(
        [brute_force, devices = run.gpu_indices, budget = run.gpu_memory_budget_bytes, mean, gpu]() {
          return std::unique_ptr<FeatureMatcher>(
              CreateBackendForOptions(brute_force, devices, budget, mean, nullptr, gpu));
        });
  }
  return std::make_unique<ExactRematchStage>(run.rematch, backend, std::move(pool));
}

}  // namespace colmap
}  // namespace cashash
