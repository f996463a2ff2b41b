#include "cashash/matchers/retaining_feature_matcher.h"

#include <algorithm>

namespace cashash {

RetainingFeatureMatcher::RetainingFeatureMatcher(std::unique_ptr<FeatureMatcher> inner, size_t budget_bytes,
                                                 std::function<size_t(const FeatureDescriptors&)> bytes_of)
    : FeatureMatcher(inner->traits()),
      inner_(std::move(inner)),
      budget_bytes_(budget_bytes),
      bytes_of_(std::move(bytes_of)) {}

void RetainingFeatureMatcher::AddImage(const Image& image) {
  const auto it = kept_.find(image.id);
  if (it != kept_.end()) {
    if (!it->second.in_use) {
      released_.erase(it->second.released);
      it->second.in_use = true;
    }
    ++stats_.images_reused;
    return;
  }
  inner_->AddImage(image);
  Kept kept;
  kept.bytes = bytes_of_(*image.descriptors);
  kept.in_use = true;
  kept_.emplace(image.id, kept);
  bytes_ += kept.bytes;
  stats_.peak_bytes = std::max(stats_.peak_bytes, bytes_);
  ++stats_.images_added;
  DropWhileOverBudget();
}

void RetainingFeatureMatcher::RemoveImage(image_t image_id) {
  const auto it = kept_.find(image_id);
  if (it == kept_.end() || !it->second.in_use) return;
  it->second.in_use = false;
  it->second.released = released_.insert(released_.end(), image_id);
  DropWhileOverBudget();
}

void RetainingFeatureMatcher::DropWhileOverBudget() {
  while (bytes_ > budget_bytes_ && !released_.empty()) {
    const image_t image_id = released_.front();
    released_.pop_front();
    const auto it = kept_.find(image_id);
    bytes_ -= it->second.bytes;
    kept_.erase(it);
    inner_->RemoveImage(image_id);
    ++stats_.images_dropped;
  }
}

std::vector<FeatureMatches> RetainingFeatureMatcher::Match(const std::vector<ImagePair>& pairs,
                                                           const std::vector<EpipolarGuide>& guides) {
  return inner_->Match(pairs, guides);
}

}  // namespace cashash
