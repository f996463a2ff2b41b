// A compact binary file of matched pairs for verification benchmarks and
// tests on machines without the databases: per pair the two cameras and the
// matched pixel positions (match k pairs point k of each image). Made from a
// matched COLMAP database by scripts/bench/dump_verification_pairs.
//
// Layout (little-endian): "CHVP", u32 version (1), u32 number of pairs; per
// pair: u32 image_id1, u32 image_id2, two cameras (i32 model_id, u64 width,
// u64 height, u8 has_prior_focal_length, u32 number of params, f64 params),
// u32 number of matches, then f32 x1 y1 x2 y2 per match.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "cashash/pipeline/batch_verifier.h"
#include "cashash/base/types.h"

namespace cashash {

struct StoredVerificationPair {
  ImagePair pair;
  Camera camera1, camera2;
  std::vector<Eigen::Vector2d> points1, points2;  // matched pixels, in match order
  FeatureMatches matches;                         // (k, k)

  // A VerificationPair pointing into this object.
  VerificationPair View(uint64_t random_seed) const;
};

// Throws std::runtime_error naming the file on I/O errors or bad contents.
void WriteVerificationPairsFile(const std::string& path, const std::vector<StoredVerificationPair>& pairs);
std::vector<StoredVerificationPair> ReadVerificationPairsFile(const std::string& path);

}  // namespace cashash
