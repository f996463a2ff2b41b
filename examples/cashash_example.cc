// Uses the installed cashash library two ways:
//   cashash_example               matches two made-up views in memory
//   cashash_example DATABASE.db   matches every pair of a COLMAP database
#include <cmath>
#include <iostream>
#include <random>

#include "cashash/matching/pair_matching.h"
#include "colmap_bridge/api/matching_api.h"

namespace {

// Two views of 500 random points, each point with its own SIFT-like
// descriptor (L2 norm about 512); the second view is shifted and its
// feature order reversed.
void MakeViews(cashash::Keypoints* kp1, cashash::FeatureDescriptors* d1, cashash::Keypoints* kp2,
               cashash::FeatureDescriptors* d2) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> coordinate(0.f, 1000.f), depth(4.f, 8.f);
  std::uniform_int_distribution<int> value(0, 60);
  const int n = 500;
  kp2->resize(n);
  d2->data.resize(n * cashash::kDescriptorDim);
  for (int i = 0; i < n; ++i) {
    const float x = coordinate(rng), y = coordinate(rng), z = depth(rng);
    cashash::Keypoint k;
    k.x = x;
    k.y = y;
    kp1->push_back(k);
    k.x = x + 400.f / z;  // parallax of a sideways step
    (*kp2)[n - 1 - i] = k;
    int raw[cashash::kDescriptorDim];
    double norm = 0;
    for (int& v : raw) {
      v = value(rng);
      norm += v * v;
    }
    for (int j = 0; j < cashash::kDescriptorDim; ++j) {
      const auto byte = static_cast<uint8_t>(std::lround(raw[j] * 512.0 / std::sqrt(norm)));
      d1->data.push_back(byte);
      d2->data[(n - 1 - i) * cashash::kDescriptorDim + j] = byte;
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  try {
    if (argc > 1) {
      cashash::colmap::MatcherCommandOptions options;
      options.use_gpu = false;
      const cashash::colmap::MatchingSummary summary = cashash::colmap::MatchExhaustive(argv[1], options);
      std::cout << summary.pipeline.pairs_done << " pairs matched, " << summary.pipeline.verified_pairs
                << " verified" << std::endl;
      return 0;
    }
    cashash::Keypoints kp1, kp2;
    cashash::FeatureDescriptors d1, d2;
    MakeViews(&kp1, &d1, &kp2, &d2);
    const cashash::PairMatchingResult result = cashash::MatchImagePair(kp1, d1, kp2, d2, {});
    std::cout << result.matches.size() << " matches, " << result.two_view_geometry.inlier_matches.size()
              << " inliers, configuration " << result.two_view_geometry.config << std::endl;
    return result.two_view_geometry.inlier_matches.size() >= 400 ? 0 : 1;
  } catch (const std::exception& e) {
    std::cerr << "ERROR: " << e.what() << std::endl;
    return 1;
  }
}
