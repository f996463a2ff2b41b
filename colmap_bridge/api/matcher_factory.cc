#include "colmap_bridge/api/matcher_factory.h"

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
#include "colmap_bridge/api/matching_api.h"
#include "colmap_bridge/api/run_gpu_resources.h"
#ifdef CASHASH_WITH_CUDA
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#endif

namespace cashash {
namespace colmap {

namespace {

#ifdef CASHASH_WITH_CUDA
// The devices of --FeatureMatching.gpu_index: "-1" (the first), "2", or a
// comma-separated list "0,1" (one matcher per device, SplitFeatureMatcher).
// Throws std::invalid_argument for anything else.
std::vector<int> GpuIndices(const std::string& gpu_index) {
  std::vector<int> indices;
  size_t at = 0;
  while (at <= gpu_index.size()) {
    const size_t comma = std::min(gpu_index.find(',', at), gpu_index.size());
    const std::string item = gpu_index.substr(at, comma - at);
    size_t used = 0;
    int value = -1;
    try {
      value = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (item.empty() || used != item.size()) {
      throw std::invalid_argument("--FeatureMatching.gpu_index: expected an integer or a comma-separated list, got '" +
                                  gpu_index + "'");
    }
    value = std::max(0, value);
    if (std::find(indices.begin(), indices.end(), value) == indices.end()) indices.push_back(value);
    at = comma + 1;
  }
  return indices;
}
#endif

}  // namespace

// The device the matcher will run on, or -1 for the CPU.
int GpuIndexForRun(const MatcherCommandOptions& options) {
#ifdef CASHASH_WITH_CUDA
  if (!options.use_gpu) return -1;
  const int gpu_index = GpuIndices(options.gpu_index).front();
  std::string reason;
  return cuda::CudaDeviceUsable(gpu_index, &reason) ? gpu_index : -1;
#else
  (void)options;
  return -1;
#endif
}

namespace {

// The backend of one matcher type (cascade or brute force): on the GPUs of
// the options where usable, else on the CPU. *on_gpu says which.
// `gpu` (may be null: each GPU matcher then owns its memory) gives each
// device's owner of memory.
std::unique_ptr<FeatureMatcher> CreateBackendForOptions(const MatcherCommandOptions& options,
                                                        size_t gpu_memory_budget_bytes, const MeanDescriptor& mean,
                                                        const std::function<void(const std::string&)>& warning,
                                                        RunGpuResources* gpu, bool* on_gpu) {
  *on_gpu = false;
  if (options.use_gpu) {
#ifdef CASHASH_WITH_CUDA
    std::vector<std::unique_ptr<FeatureMatcher>> parts;
    std::string reason;
    for (const int gpu_index : GpuIndices(options.gpu_index)) {
      std::string why;
      if (!cuda::CudaDeviceUsable(gpu_index, &why)) {
        reason += (reason.empty() ? "" : "; ") + std::string("device ") + std::to_string(gpu_index) + ": " + why;
        continue;
      }
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
    if (!parts.empty()) {
      *on_gpu = true;
      if (!reason.empty() && warning) warning("not every listed GPU is usable (" + reason + "); matching on the others");
      if (parts.size() == 1) return std::move(parts[0]);
      // Several devices share every chunk of pairs.
      return std::make_unique<SplitFeatureMatcher>(std::move(parts));
    }
    if (warning) warning("no usable CUDA device (" + reason + "); matching on the CPU");
#else
    (void)gpu;
    if (warning) warning("cashash was built without CUDA; matching on the CPU");
#endif
  }
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
  if (GpuIndices(run.options.gpu_index).size() != 1) return nullptr;
  MatcherCommandOptions brute_force = run.options;
  brute_force.cashash.matcher = MatcherType::kBruteForce;
  return std::make_shared<ExactMatcherPool>([brute_force, budget = run.gpu_memory_budget_bytes, mean, gpu]() {
    bool on_gpu = false;
    return CreateBackendForOptions(brute_force, budget, mean, nullptr, gpu, &on_gpu);
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
                                                    RunGpuResources* gpu, bool* on_gpu) {
  const MatcherCommandOptions& options = run.options;
  MatcherCommandOptions cascade = options;
  cascade.cashash.matcher = MatcherType::kCascade;
  std::unique_ptr<FeatureMatcher> matcher =
      CreateBackendForOptions(cascade, run.gpu_memory_budget_bytes, mean, warning, gpu, on_gpu);
  if (options.guided.enabled || options.cashash.exact_rematch_min_matches <= 0) return matcher;
  return std::make_unique<ExactRematchFeatureMatcher>(
      std::move(matcher), static_cast<size_t>(options.cashash.exact_rematch_min_matches), counts,
      *on_gpu ? DeferredRematchPool(run, mean, gpu) : nullptr,
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
  bool on_gpu = false;
  if (options.cashash.matcher == MatcherType::kCascade) {
    return CreateCascadeForRun(run, mean, warning, counts, gpu, &on_gpu);
  }
  return CreateBackendForOptions(options, run.gpu_memory_budget_bytes, mean, warning, gpu, &on_gpu);
}

}  // namespace colmap
}  // namespace cashash
