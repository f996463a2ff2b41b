#include "cashash/matchers/retaining_feature_matcher.h"

#include <algorithm>

namespace cashash {

RetainingFeatureMatcher::RetainingFeatureMatcher(std::unique_ptr<FeatureMatcher> inner, size_t budget_bytes,
                                                 std::function<size_t(const FeatureDescriptors&)> bytes_of)
    : inner_(std::move(inner)), budget_bytes_(budget_bytes), bytes_of_(std::move(bytes_of)) {}

void RetainingFeatureMatcher::AddImage(image_t image_id, const FeatureDescriptors& descriptors) {
  Add(image_id, descriptors, [&] { inner_->AddImage(image_id, descriptors); });
}

void RetainingFeatureMatcher::AddSharedImage(image_t image_id, std::shared_ptr<const FeatureDescriptors> descriptors) {
  Add(image_id, *descriptors, [&] { inner_->AddSharedImage(image_id, descriptors); });
}

void RetainingFeatureMatcher::Add(image_t image_id, const FeatureDescriptors& descriptors,
                                  const std::function<void()>& add_to_inner) {
  const auto it = kept_.find(image_id);
  if (it != kept_.end()) {
    if (!it->second.in_use) {
      released_.erase(it->second.released);
      it->second.in_use = true;
    }
    ++stats_.images_reused;
    return;
  }
  add_to_inner();
  Kept kept;
  kept.bytes = bytes_of_(descriptors);
  kept.in_use = true;
  kept_.emplace(image_id, kept);
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

std::vector<FeatureMatches> RetainingFeatureMatcher::MatchPairs(const std::vector<ImagePair>& pairs) {
  return inner_->MatchPairs(pairs);
}

ChunkMatches RetainingFeatureMatcher::MatchPairsDeferred(const std::vector<ImagePair>& pairs) {
  return inner_->MatchPairsDeferred(pairs);
}

std::string RetainingFeatureMatcher::Name() const { return inner_->Name(); }

}  // namespace cashash
