#include "colmap_bridge/api/matcher_factory.h"

#include <algorithm>
#include <cstdlib>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "cashash/matchers/exact_rematch_feature_matcher.h"
#include "cashash/matchers/fallback_feature_matcher.h"
#include "cashash/matchers/split_feature_matcher.h"
#include "cashash/matching/matcher_choice.h"
#include "cashash/matching/table_shape.h"
#include "colmap_bridge/api/matching_api.h"
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
std::unique_ptr<FeatureMatcher> CreateBackendForOptions(const MatcherCommandOptions& options,
                                                        const MeanDescriptor& mean,
                                                        const std::function<void(const std::string&)>& warning,
                                                        bool* on_gpu) {
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
      // A run that outgrows the card (device memory) finishes on the CPU.
      parts.push_back(CreateFallbackFeatureMatcher(
          cuda::CreateGpuFeatureMatcher(options.sift, options.cashash, mean, gpu_index),
          [sift = options.sift, cashash = options.cashash, mean]() {
            return CreateCpuFeatureMatcher(sift, cashash, mean);
          },
          IsDeviceMemoryError, warning));
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
    if (warning) warning("cashash was built without CUDA; matching on the CPU");
#endif
  }
  return CreateCpuFeatureMatcher(options.sift, options.cashash, mean);
}

// Brute-force matchers on the run's GPU for the exact rematch deferred to the
// verification threads (exact_rematch_feature_matcher.h); null where it
// stays on the matching thread: with several GPUs (each chunk is split
// between them), or where options.rematch_on_matching_thread says so.
// CASHASH_DEFERRED_REMATCH=0 or 1 overrides the latter, to compare.
std::shared_ptr<ExactMatcherPool> DeferredRematchPool(const MatcherCommandOptions& options,
                                                      const MeanDescriptor& mean) {
#ifdef CASHASH_WITH_CUDA
  const char* setting = std::getenv("CASHASH_DEFERRED_REMATCH");
  bool deferred = !options.rematch_on_matching_thread;
  if (setting != nullptr && std::string(setting) == "0") deferred = false;
  if (setting != nullptr && std::string(setting) == "1") deferred = true;
  if (!deferred) return nullptr;
  if (GpuIndices(options.gpu_index).size() != 1) return nullptr;
  MatcherCommandOptions brute_force = options;
  brute_force.cashash.matcher = MatcherType::kBruteForce;
  return std::make_shared<ExactMatcherPool>([brute_force, mean]() {
    bool on_gpu = false;
    return CreateBackendForOptions(brute_force, mean, nullptr, &on_gpu);
  });
#else
  (void)options;
  (void)mean;
  return nullptr;
#endif
}

// The cascade backend of a run; with --CasHash.exact_rematch_min_matches > 0
// it also matches the pairs that may verify again exactly, from the
// descriptors it holds (exact_rematch_feature_matcher.h). Guided matching
// keeps the bare cascade: its stage 2 screens by the epipolar band.
std::unique_ptr<FeatureMatcher> CreateCascadeForOptions(const MatcherCommandOptions& options,
                                                        const MeanDescriptor& mean,
                                                        const std::function<void(const std::string&)>& warning,
                                                        const std::shared_ptr<ExactRematchCounts>& counts,
                                                        bool* on_gpu) {
  MatcherCommandOptions cascade = options;
  cascade.cashash.matcher = MatcherType::kCascade;
  std::unique_ptr<FeatureMatcher> matcher = CreateBackendForOptions(cascade, mean, warning, on_gpu);
  if (options.guided.enabled || options.cashash.exact_rematch_min_matches <= 0) return matcher;
  return std::make_unique<ExactRematchFeatureMatcher>(
      std::move(matcher), static_cast<size_t>(options.cashash.exact_rematch_min_matches), counts,
      *on_gpu ? DeferredRematchPool(options, mean) : nullptr,
      static_cast<size_t>(std::max(0, options.cashash.exact_rematch_max_matches)));
}

// --CasHash.matcher auto decided from the run's data (matcher_choice.h).
MatcherChoice AutoMatcherChoice(const MatcherCommandOptions& options, size_t features) {
  MatcherChoiceInput input;
  input.on_gpu = GpuIndexForRun(options) >= 0;
  input.features_per_image = features;
  // The runs' threshold, not typed: a value set through the library (the
  // Python module's options) is kept, as for the bucket screening shape.
  input.rematch_from_rule = options.rematch_min_matches_from_shape &&
                            options.cashash.exact_rematch_min_matches == kDefaultRematchMinMatches &&
                            options.cashash.exact_rematch_max_matches == 0;
  input.guided = options.guided.enabled;
  return ChooseAutoMatcher(options.cashash, input);
}

}  // namespace

int RunTau(const MatcherCommandOptions& options) {
  if (options.cashash.tau > 0) return options.cashash.tau;
  return ChooseCascadeTau(options.cashash.exact_rematch_min_matches, options.guided.enabled,
                          options.cashash.exact_rematch_max_matches);
}

std::unique_ptr<FeatureMatcher> CreateMatcherForOptions(const MatcherCommandOptions& given,
                                                        const MeanDescriptor& mean,
                                                        const std::function<void(const std::string&)>& warning,
                                                        const std::function<void(const std::string&)>& info,
                                                        const std::shared_ptr<ExactRematchCounts>& counts) {
  // Options not passed through ResolveOptionsForRun get their matcher and
  // tau here too.
  MatcherCommandOptions options = given;
  if (options.cashash.matcher == MatcherType::kAuto) {
    options.cashash = ApplyMatcherChoice(options.cashash, AutoMatcherChoice(options, 0));
  }
  options.cashash.tau = RunTau(options);
  bool on_gpu = false;
  if (options.cashash.matcher == MatcherType::kCascade) {
    return CreateCascadeForOptions(options, mean, warning, counts, &on_gpu);
  }
  // auto was resolved above: brute force as set by the options.
  (void)info;
  return CreateBackendForOptions(options, mean, warning, &on_gpu);
}

MatcherCommandOptions ResolveOptionsForRun(const MatcherCommandOptions& options,
                                           const std::vector<size_t>& rows_per_image,
                                           const std::function<void(const std::string&)>& info) {
  MatcherCommandOptions resolved = options;
  const size_t features = TypicalFeatureCount(rows_per_image, options.sift.max_num_matches);
  if (resolved.cashash.matcher == MatcherType::kAuto) {
    const MatcherChoice choice = AutoMatcherChoice(resolved, features);
    resolved.cashash = ApplyMatcherChoice(resolved.cashash, choice);
    if (info) info("Matcher: " + choice.reason);
  }
  const TableShapeGoal goal =
      CascadeOnlyScreens(resolved.cashash.exact_rematch_min_matches, resolved.guided.enabled,
                         resolved.cashash.exact_rematch_max_matches)
          ? TableShapeGoal::kScreening
          : TableShapeGoal::kRecall;
  resolved.cashash = ResolveTableShape(resolved.cashash, features, goal);
  // Fewer tables find fewer of a pair's true matches: the threshold the
  // bucket screening shape was measured with (table_shape.h).
  const bool bucket_screen =
      IsBucketScreeningShape(features, options.cashash.num_tables, options.cashash.bits_per_table, goal);
  const bool rematch_from_shape = options.rematch_min_matches_from_shape &&
                                  options.cashash.exact_rematch_min_matches == kDefaultRematchMinMatches && bucket_screen;
  if (rematch_from_shape) resolved.cashash.exact_rematch_min_matches = kBucketScreeningRematchMinMatches;
  // Its screen is light: the matching thread has room for the rematch.
  if (bucket_screen) resolved.rematch_on_matching_thread = true;
  resolved.cashash.tau = RunTau(resolved);
  if (info && resolved.cashash.matcher != MatcherType::kBruteForce) {
    std::string text =
        DescribeTableShape(options.cashash, resolved.cashash, features, rows_per_image.size(), goal);
    text += "; tau " + std::to_string(resolved.cashash.tau);
    if (options.cashash.tau == 0) {
      text += resolved.cashash.tau == kCascadeTauForScreening
                  ? " (chosen: the exact rematch decides the pairs that may verify)"
                  : " (chosen: the cascade's own matches are kept)";
    }
    if (rematch_from_shape) {
      text += "; exact rematch from " + std::to_string(resolved.cashash.exact_rematch_min_matches) +
              " cascade matches (chosen for these tables)";
    }
    info(text);
  }
  return resolved;
}

}  // namespace colmap
}  // namespace cashash
