#include "colmap_bridge/blob_codec.h"

#include <cmath>
#include <cstddef>
#include <cstring>

#include "colmap_bridge/database.h"

namespace cashash {
namespace colmap {
namespace {

// rows x cols must be non-negative and fill the blob exactly. The product is
// checked for overflow first: a corrupt row claiming 2^62 rows must not wrap
// around to the blob's size and then size an allocation.
void CheckShape(const MatrixBlob& blob, size_t element_size, const std::string& owner) {
  if (blob.rows < 0 || blob.cols < 0) {
    throw DatabaseError(owner + ": negative shape rows x cols = " + std::to_string(blob.rows) +
                        " x " + std::to_string(blob.cols));
  }
  size_t expected = 0;
  const bool overflow =
      __builtin_mul_overflow(static_cast<size_t>(blob.rows), static_cast<size_t>(blob.cols),
                             &expected) ||
      __builtin_mul_overflow(expected, element_size, &expected);
  if (overflow || blob.num_bytes != expected) {
    throw DatabaseError(owner + ": blob size " + std::to_string(blob.num_bytes) +
                        " does not match rows x cols = " + std::to_string(blob.rows) + " x " +
                        std::to_string(blob.cols) + " of " + std::to_string(element_size) +
                        "-byte values (" +
                        (overflow ? std::string("more than 2^64") : std::to_string(expected)) +
                        " bytes)");
  }
}

}  // namespace

std::string DescriptorTypeName(int64_t type) {
  switch (type) {
    case 0: return "SIFT";
    case 1: return "ALIKED_N16ROT";
    case 2: return "ALIKED_N32";
    default: return "UNKNOWN";
  }
}

Keypoints DecodeKeypoints(const MatrixBlob& blob, const std::string& owner) {
  if (blob.cols != 2 && blob.cols != 4 && blob.cols != 6) {
    throw DatabaseError(owner + ": expected float32 keypoints with 2, 4 or 6 columns, found " +
                        std::to_string(blob.cols) + " columns");
  }
  CheckShape(blob, sizeof(float), owner);
  const size_t rows = static_cast<size_t>(blob.rows);
  const size_t cols = static_cast<size_t>(blob.cols);
  std::vector<float> values(rows * cols);
  if (!values.empty()) std::memcpy(values.data(), blob.data, blob.num_bytes);

  Keypoints keypoints(rows);
  for (size_t i = 0; i < rows; ++i) {
    const float* v = values.data() + i * cols;
    Keypoint& kp = keypoints[i];
    kp.x = v[0];
    kp.y = v[1];
    for (size_t c = 0; c < cols; ++c) {
      // NaN or infinite values would poison RANSAC and the watermark test.
      if (!std::isfinite(v[c])) {
        throw DatabaseError(owner + ": row " + std::to_string(i) + " holds a non-finite value (" +
                            std::to_string(v[c]) + ") in column " + std::to_string(c));
      }
    }
    if (cols == 4) {
      // (scale, orientation) -> the rotation-scaled identity shape.
      const float scale = v[2];
      const float orientation = v[3];
      kp.a11 = scale * std::cos(orientation);
      kp.a12 = -scale * std::sin(orientation);
      kp.a21 = scale * std::sin(orientation);
      kp.a22 = scale * std::cos(orientation);
    } else if (cols == 6) {
      kp.a11 = v[2];
      kp.a12 = v[3];
      kp.a21 = v[4];
      kp.a22 = v[5];
    }
  }
  return keypoints;
}

std::vector<float> EncodeKeypoints(const Keypoints& keypoints, int num_columns) {
  if (num_columns != 2 && num_columns != 4 && num_columns != 6) {
    throw DatabaseError("keypoints are stored with 2, 4 or 6 columns, not " + std::to_string(num_columns));
  }
  const size_t cols = static_cast<size_t>(num_columns);
  std::vector<float> values(keypoints.size() * cols);
  for (size_t i = 0; i < keypoints.size(); ++i) {
    const Keypoint& kp = keypoints[i];
    float* v = values.data() + i * cols;
    v[0] = kp.x;
    v[1] = kp.y;
    if (cols == 4) {
      v[2] = kp.ComputeScale();
      v[3] = std::atan2(kp.a21, kp.a11);
    } else if (cols == 6) {
      v[2] = kp.a11;
      v[3] = kp.a12;
      v[4] = kp.a21;
      v[5] = kp.a22;
    }
  }
  return values;
}

FeatureDescriptors DecodeSiftDescriptors(const MatrixBlob& blob, const std::string& owner) {
  if (blob.cols != kDescriptorDim) {
    throw DatabaseError(owner + ": expected uint8 x " + std::to_string(kDescriptorDim) +
                        " SIFT descriptors, found " + std::to_string(blob.cols) + " columns");
  }
  // rows is bounded first so that rows x 512 cannot wrap around.
  if (blob.rows > 0 && static_cast<uint64_t>(blob.rows) < (uint64_t{1} << 40) &&
      blob.num_bytes == static_cast<size_t>(blob.rows) * kDescriptorDim * sizeof(float)) {
    throw DatabaseError(owner + ": blob size " + std::to_string(blob.num_bytes) +
                        " does not match rows x cols = " + std::to_string(blob.rows) + " x " +
                        std::to_string(blob.cols) +
                        " bytes; it holds float32 values, expected uint8 SIFT descriptors");
  }
  CheckShape(blob, sizeof(uint8_t), owner);
  FeatureDescriptors descriptors;
  descriptors.data.resize(blob.num_bytes);
  if (blob.num_bytes > 0) std::memcpy(descriptors.data.data(), blob.data, blob.num_bytes);
  return descriptors;
}

FeatureMatches DecodeMatches(const MatrixBlob& blob, bool swap, const std::string& owner) {
  if (blob.rows == 0 && blob.num_bytes == 0) return {};
  if (blob.cols != 2) {
    throw DatabaseError(owner + ": expected uint32 N x 2 matches, found " +
                        std::to_string(blob.cols) + " columns");
  }
  CheckShape(blob, sizeof(uint32_t), owner);
  std::vector<uint32_t> values(static_cast<size_t>(blob.rows) * 2);
  if (!values.empty()) std::memcpy(values.data(), blob.data, blob.num_bytes);
  FeatureMatches matches(static_cast<size_t>(blob.rows));
  for (size_t i = 0; i < matches.size(); ++i) {
    matches[i].point2D_idx1 = values[2 * i + (swap ? 1 : 0)];
    matches[i].point2D_idx2 = values[2 * i + (swap ? 0 : 1)];
  }
  return matches;
}

std::vector<uint32_t> EncodeMatches(const FeatureMatches& matches, bool swap) {
  std::vector<uint32_t> values(matches.size() * 2);
  for (size_t i = 0; i < matches.size(); ++i) {
    values[2 * i] = swap ? matches[i].point2D_idx2 : matches[i].point2D_idx1;
    values[2 * i + 1] = swap ? matches[i].point2D_idx1 : matches[i].point2D_idx2;
  }
  return values;
}

static_assert(sizeof(FeatureMatch) == 2 * sizeof(uint32_t) && offsetof(FeatureMatch, point2D_idx1) == 0 &&
                  offsetof(FeatureMatch, point2D_idx2) == sizeof(uint32_t) && sizeof(point2D_t) == sizeof(uint32_t),
              "FeatureMatch must be laid out as a stored match row");

const void* MatchesAsStored(const FeatureMatches& matches) { return matches.data(); }

std::array<double, 9> EncodeMatrix3d(const Eigen::Matrix3d& matrix) {
  std::array<double, 9> values;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) values[3 * r + c] = matrix(r, c);
  }
  return values;
}

Eigen::Matrix3d DecodeMatrix3d(const void* data, size_t num_bytes, const std::string& owner) {
  if (num_bytes == 0) return Eigen::Matrix3d::Zero();
  if (num_bytes != 9 * sizeof(double)) {
    throw DatabaseError(owner + ": expected 9 float64 values (72 bytes), found " +
                        std::to_string(num_bytes) + " bytes");
  }
  double values[9];
  std::memcpy(values, data, sizeof(values));
  Eigen::Matrix3d matrix;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) matrix(r, c) = values[3 * r + c];
  }
  return matrix;
}

template <int N>
Eigen::Matrix<double, N, 1> DecodeVector(const void* data, size_t num_bytes,
                                         const Eigen::Matrix<double, N, 1>& fallback,
                                         const std::string& owner) {
  if (num_bytes == 0) return fallback;
  if (num_bytes != N * sizeof(double)) {
    throw DatabaseError(owner + ": expected " + std::to_string(N) + " float64 values, found " +
                        std::to_string(num_bytes) + " bytes");
  }
  Eigen::Matrix<double, N, 1> vector;
  std::memcpy(vector.data(), data, num_bytes);
  return vector;
}

template Eigen::Matrix<double, 3, 1> DecodeVector<3>(const void*, size_t,
                                                     const Eigen::Matrix<double, 3, 1>&,
                                                     const std::string&);
template Eigen::Matrix<double, 4, 1> DecodeVector<4>(const void*, size_t,
                                                     const Eigen::Matrix<double, 4, 1>&,
                                                     const std::string&);

}  // namespace colmap
}  // namespace cashash
