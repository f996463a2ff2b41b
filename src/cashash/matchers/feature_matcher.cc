#include "cashash/matchers/feature_matcher.h"

#include <stdexcept>
#include <string>

namespace cashash {

void FeatureMatcher::AddImage(image_t image_id, const FeatureDescriptors& descriptors) {
  Image image;
  image.id = image_id;
  image.descriptors = std::make_shared<const FeatureDescriptors>(descriptors);
  AddImage(image);
}

void FeatureMatcher::CheckGuides(const std::vector<ImagePair>& pairs, const std::vector<EpipolarGuide>& guides) const {
  if (guides.empty()) return;
  if (!traits_.epipolar_guidance) {
    throw std::logic_error("the " + traits_.name + " matcher does not support epipolar-guided matching");
  }
  if (guides.size() != pairs.size()) {
    throw std::invalid_argument("Match: " + std::to_string(guides.size()) + " epipolar guides for " +
                                std::to_string(pairs.size()) + " pairs");
  }
}

}  // namespace cashash
