// Matched pairs shaped like those of real photographs, made inside the test
// (nothing to download or extract): a street of images from the database
// generator (synthetic/database_generator.h: cameras with focal priors,
// keypoint noise, distractor features, SIFT-like descriptors with noise of
// their own; neighbouring images overlap and far ones do not), matched
// exhaustively by the CPU cascade. The pairs hold the raw matches, wrong
// ones included, as a verifier receives them in a run.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "cashash/matchers/exact_matcher.h"
#include "cashash/matching/mean_descriptor.h"
#include "cashash/pipeline/verification_pairs_file.h"
#include "colmap_bridge/database_pipeline_io.h"
#include "cascade_options.h"
#include "generated_database_support.h"
#include "synthetic/database_generator.h"

namespace cashash {
namespace testing_support {

struct GeneratedStreet {
  std::vector<ImageFeatures> images;  // in image_id order
  std::vector<Camera> cameras;        // of each image
};

// `num_images` images of exactly `num_features` features each, generated
// into a database under `dir` and read back.
inline GeneratedStreet GenerateStreet(const ScratchDir& dir, int num_images, int num_features, uint64_t seed) {
  const std::string source = dir.File("street_source.db");
  WriteRandomSourceDatabase(source, 4, 2000);
  colmap::DatabaseGeneratorOptions options;
  options.database_path = dir.File("street.db");
  options.source_database_path = source;
  options.num_images = num_images;
  options.num_features = num_features;
  options.random_seed = seed;
  colmap::GenerateDatabase(options);
  colmap::DatabaseFeatureSource database(options.database_path);
  GeneratedStreet street;
  for (const Image& image : database.images()) {
    street.images.push_back(database.LoadFeatures(image.image_id));
    street.images.back().image_id = image.image_id;
    street.cameras.push_back(database.CameraOfImage(image.image_id));
  }
  return street;
}

// Every pair of the street with at least `min_matches` raw matches of the
// CPU cascade (default SIFT options, CascadeOptions), in the layout of a verification
// pairs file: match k pairs point k of each image.
inline std::vector<StoredVerificationPair> MatchedStreetPairs(const GeneratedStreet& street, size_t min_matches) {
  std::vector<const FeatureDescriptors*> descriptors;
  for (const ImageFeatures& image : street.images) descriptors.push_back(&image.descriptors);
  std::unique_ptr<FeatureMatcher> matcher =
      CreateCpuFeatureMatcher(SiftMatchingOptions(), CascadeOptions(), ComputeMeanDescriptor(descriptors));
  std::vector<ImagePair> pairs;
  for (size_t i = 0; i < street.images.size(); ++i) {
    matcher->AddImage(street.images[i].image_id, street.images[i].descriptors);
    for (size_t j = i + 1; j < street.images.size(); ++j) {
      pairs.emplace_back(street.images[i].image_id, street.images[j].image_id);
    }
  }
  const std::vector<FeatureMatches> matches = matcher->Match(pairs);
  std::vector<StoredVerificationPair> stored;
  size_t p = 0;
  for (size_t i = 0; i < street.images.size(); ++i) {
    for (size_t j = i + 1; j < street.images.size(); ++j, ++p) {
      if (matches[p].empty() || matches[p].size() < min_matches) continue;
      StoredVerificationPair pair;
      pair.pair = pairs[p];
      pair.camera1 = street.cameras[i];
      pair.camera2 = street.cameras[j];
      for (const FeatureMatch& m : matches[p]) {
        const Keypoint& a = street.images[i].keypoints.at(m.point2D_idx1);
        const Keypoint& b = street.images[j].keypoints.at(m.point2D_idx2);
        const auto k = static_cast<point2D_t>(pair.points1.size());
        pair.points1.emplace_back(a.x, a.y);
        pair.points2.emplace_back(b.x, b.y);
        pair.matches.push_back({k, k});
      }
      stored.push_back(std::move(pair));
    }
  }
  return stored;
}

// The pairs of a generated street of `num_images` x `num_features`.
inline std::vector<StoredVerificationPair> GeneratedStreetPairs(const std::string& tag, int num_images,
                                                                int num_features, uint64_t seed,
                                                                size_t min_matches = 1) {
  const ScratchDir dir(tag);
  return MatchedStreetPairs(GenerateStreet(dir, num_images, num_features, seed), min_matches);
}

}  // namespace testing_support
}  // namespace cashash
