#include "cashash/matchers/fallback_feature_matcher.h"

#include <map>
#include <utility>
#include <vector>

#include "cashash/base/device_memory_error.h"

namespace cashash {
namespace {

class FallbackFeatureMatcher : public MatchingBackend {
 public:
  FallbackFeatureMatcher(std::unique_ptr<MatchingBackend> primary,
                         std::function<std::unique_ptr<MatchingBackend>()> make_fallback,
                         std::function<bool(const std::exception&)> recoverable,
                         std::function<void(const std::string&)> warn)
      : MatchingBackend(primary->traits()),
        active_(std::move(primary)),
        make_fallback_(std::move(make_fallback)),
        recoverable_(std::move(recoverable)),
        warn_(std::move(warn)) {}

  void AddImage(const Image& image) override {
    // The caller's own handle is what the fallback is rebuilt from: no
    // copy, and the features stay alive only while this matcher holds the
    // image.
    if (!fell_back_) images_[image.id] = image;
    Run([&] { active_->AddImage(image); });
  }
  using FeatureMatcher::AddImage;

  void RemoveImage(image_t image_id) override {
    images_.erase(image_id);
    active_->RemoveImage(image_id);
  }

  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& guides = {}) override {
    std::vector<FeatureMatches> result;
    Run([&] { result = active_->Match(pairs, guides); });
    return result;
  }

  std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) override {
    std::vector<FeatureMatches> result;
    Run([&] { result = active_->MatchExact(pairs); });
    return result;
  }

  std::unique_ptr<ExactMatcher> HoldForExact(const std::vector<ImagePair>& pairs) override {
    std::unique_ptr<ExactMatcher> held;
    Run([&] { held = active_->HoldForExact(pairs); });
    return held;
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
      for (const auto& entry : images_) active_->AddImage(entry.second);
      images_.clear();
      step();
    }
  }

  std::unique_ptr<MatchingBackend> active_;
  std::function<std::unique_ptr<MatchingBackend>()> make_fallback_;
  std::function<bool(const std::exception&)> recoverable_;
  std::function<void(const std::string&)> warn_;
  std::map<image_t, Image> images_;
  bool fell_back_ = false;
};

}  // namespace

std::unique_ptr<MatchingBackend> CreateFallbackFeatureMatcher(
    std::unique_ptr<MatchingBackend> primary, std::function<std::unique_ptr<MatchingBackend>()> make_fallback,
    std::function<bool(const std::exception&)> recoverable, std::function<void(const std::string&)> warn) {
  return std::make_unique<FallbackFeatureMatcher>(std::move(primary), std::move(make_fallback),
                                                  std::move(recoverable), std::move(warn));
}

bool IsDeviceMemoryError(const std::exception& error) {
  return dynamic_cast<const DeviceMemoryError*>(&error) != nullptr;
}

}  // namespace cashash
