#include "cashash/matchers/fallback_feature_matcher.h"

#include <map>

#include "cashash/base/device_memory_error.h"

namespace cashash {
namespace {

class FallbackFeatureMatcher : public FeatureMatcher {
 public:
  FallbackFeatureMatcher(std::unique_ptr<FeatureMatcher> primary,
                         std::function<std::unique_ptr<FeatureMatcher>()> make_fallback,
                         std::function<bool(const std::exception&)> recoverable,
                         std::function<void(const std::string&)> warn)
      : active_(std::move(primary)),
        make_fallback_(std::move(make_fallback)),
        recoverable_(std::move(recoverable)),
        warn_(std::move(warn)) {}

  void AddImage(image_t image_id, const FeatureDescriptors& descriptors) override {
    // The host copy is what the fallback is rebuilt from; the caller's
    // descriptors may go away once we return.
    if (!fell_back_) images_[image_id] = std::make_shared<const FeatureDescriptors>(descriptors);
    Run([&] { active_->AddImage(image_id, descriptors); });
  }

  void AddSharedImage(image_t image_id, std::shared_ptr<const FeatureDescriptors> descriptors) override {
    // The pipeline's own handle: no copy, and the features stay alive only
    // while this matcher holds the image.
    if (!fell_back_) images_[image_id] = descriptors;
    Run([&] { active_->AddSharedImage(image_id, descriptors); });
  }

  void RemoveImage(image_t image_id) override {
    images_.erase(image_id);
    active_->RemoveImage(image_id);
  }

  std::vector<FeatureMatches> MatchPairs(const std::vector<ImagePair>& pairs) override {
    std::vector<FeatureMatches> result;
    Run([&] { result = active_->MatchPairs(pairs); });
    return result;
  }

  std::string Name() const override { return active_->Name(); }

  bool SupportsEpipolarGuidance() const override { return active_->SupportsEpipolarGuidance(); }

  std::vector<FeatureMatches> MatchPairsGuided(const std::vector<GuidedPair>& pairs, double max_distance) override {
    std::vector<FeatureMatches> result;
    Run([&] { result = active_->MatchPairsGuided(pairs, max_distance); });
    return result;
  }

  bool SupportsExactMatching() const override { return active_->SupportsExactMatching(); }
  // The active backend's ticket (the CPU backends give none).
  std::unique_ptr<ExactMatchingTicket> DeferExactMatching(const std::vector<ImagePair>& pairs) override {
    return active_->DeferExactMatching(pairs);
  }

  std::vector<FeatureMatches> MatchPairsExact(const std::vector<ImagePair>& pairs) override {
    std::vector<FeatureMatches> result;
    Run([&] { result = active_->MatchPairsExact(pairs); });
    return result;
  }

 private:
  template <typename Step>
  void Run(Step step) {
    if (fell_back_) return step();
    try {
      step();
    } catch (const std::exception& error) {
      if (!recoverable_(error)) throw;
      const std::string what = error.what();
      const std::string from = active_->Name();
      active_.reset();  // frees the device memory first
      active_ = make_fallback_();
      fell_back_ = true;
      if (warn_) warn_(from + " failed (" + what + "); continuing on " + active_->Name());
      for (const auto& [id, descriptors] : images_) active_->AddImage(id, *descriptors);
      images_.clear();
      step();
    }
  }

  std::unique_ptr<FeatureMatcher> active_;
  std::function<std::unique_ptr<FeatureMatcher>()> make_fallback_;
  std::function<bool(const std::exception&)> recoverable_;
  std::function<void(const std::string&)> warn_;
  std::map<image_t, std::shared_ptr<const FeatureDescriptors>> images_;
  bool fell_back_ = false;
};

}  // namespace

std::unique_ptr<FeatureMatcher> CreateFallbackFeatureMatcher(
    std::unique_ptr<FeatureMatcher> primary, std::function<std::unique_ptr<FeatureMatcher>()> make_fallback,
    std::function<bool(const std::exception&)> recoverable, std::function<void(const std::string&)> warn) {
  return std::make_unique<FallbackFeatureMatcher>(std::move(primary), std::move(make_fallback),
                                                  std::move(recoverable), std::move(warn));
}

bool IsDeviceMemoryError(const std::exception& error) {
  return dynamic_cast<const DeviceMemoryError*>(&error) != nullptr;
}

}  // namespace cashash
