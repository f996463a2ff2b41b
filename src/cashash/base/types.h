// Plain data types shared by every part of cashash: features, matches,
// cameras. Nothing here knows about COLMAP's database or about CUDA.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace cashash {

using image_t = uint32_t;
using camera_t = uint32_t;
using point2D_t = uint32_t;
using pair_t = uint64_t;

// SIFT descriptors are 128 bytes; this is the only descriptor type we match.
constexpr int kDescriptorDim = 128;

// A keypoint as COLMAP stores it: position (upper-left pixel centre at
// (0.5, 0.5)) and the affine shape [a11 a12; a21 a22]. Databases with 2 or 4
// columns are converted to this form on reading.
struct Keypoint {
  float x = 0.f;
  float y = 0.f;
  float a11 = 1.f;
  float a12 = 0.f;
  float a21 = 0.f;
  float a22 = 1.f;

  // Mean of the two axis scales, as COLMAP's FeatureKeypoint::ComputeScale.
  float ComputeScale() const {
    return 0.5f * (std::sqrt(a11 * a11 + a21 * a21) + std::sqrt(a12 * a12 + a22 * a22));
  }
};
using Keypoints = std::vector<Keypoint>;

// Row-major N x 128 uint8 SIFT descriptors.
struct FeatureDescriptors {
  std::vector<uint8_t> data;

  size_t rows() const { return data.size() / kDescriptorDim; }
  const uint8_t* row(size_t i) const { return data.data() + i * kDescriptorDim; }
};

// A correspondence between feature idx1 of the first and idx2 of the second
// image of a pair (0-based rows of keypoints/descriptors).
struct FeatureMatch {
  point2D_t point2D_idx1 = 0;
  point2D_t point2D_idx2 = 0;
  bool operator==(const FeatureMatch& o) const {
    return point2D_idx1 == o.point2D_idx1 && point2D_idx2 == o.point2D_idx2;
  }
  bool operator<(const FeatureMatch& o) const {
    return point2D_idx1 != o.point2D_idx1 ? point2D_idx1 < o.point2D_idx1
                                          : point2D_idx2 < o.point2D_idx2;
  }
};
using FeatureMatches = std::vector<FeatureMatch>;

// A camera as COLMAP stores it. model_id follows COLMAP's numbering
// (SIMPLE_PINHOLE 0, PINHOLE 1, SIMPLE_RADIAL 2, RADIAL 3, OPENCV 4, ...).
struct Camera {
  camera_t camera_id = 0;
  int model_id = 0;
  uint64_t width = 0;
  uint64_t height = 0;
  std::vector<double> params;
  bool has_prior_focal_length = false;
};

struct Image {
  image_t image_id = 0;
  std::string name;
  camera_t camera_id = 0;
};

// Everything the matcher and the verifier need of one image.
struct ImageFeatures {
  image_t image_id = 0;
  Keypoints keypoints;
  FeatureDescriptors descriptors;
};

using ImagePair = std::pair<image_t, image_t>;

}  // namespace cashash
