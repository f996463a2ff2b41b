// Conversions between COLMAP's database blobs and cashash types, with the
// validation that turns a malformed row into one clear error line. No SQLite
// in here: the functions see (rows, cols, bytes) as read from a row.
// Blobs are little-endian, as COLMAP writes them; we only build for
// little-endian hosts.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "cashash/base/types.h"

namespace cashash {
namespace colmap {

// One dynamic-size matrix cell of a row: rows, cols and the data blob.
struct MatrixBlob {
  int64_t rows = 0;
  int64_t cols = 0;
  const void* data = nullptr;  // may be null when num_bytes is 0
  size_t num_bytes = 0;
};

// COLMAP's FeatureExtractorType names for the descriptors.type column:
// SIFT 0, ALIKED_N16ROT 1, ALIKED_N32 2; "UNKNOWN" otherwise.
std::string DescriptorTypeName(int64_t type);
constexpr int64_t kSiftDescriptorType = 0;

// float32 keypoints with 2 (x, y), 4 (x, y, scale, orientation) or 6
// (x, y, a11, a12, a21, a22) columns, converted to the 6-column form.
// `owner` names the row in errors, e.g. "keypoints of image 3 (a.jpg)".
Keypoints DecodeKeypoints(const MatrixBlob& blob, const std::string& owner);

// The inverse of DecodeKeypoints: 2 (x, y), 4 (x, y, scale, orientation,
// from the affine part) or 6 columns, row-major float32 values.
std::vector<float> EncodeKeypoints(const Keypoints& keypoints, int num_columns);

// uint8 x 128 SIFT descriptors; anything else (other width, float data, a
// size that does not match rows x cols) throws naming `owner`.
FeatureDescriptors DecodeSiftDescriptors(const MatrixBlob& blob, const std::string& owner);

// uint32 N x 2 row-major matches; `swap` exchanges the two columns (the
// pair was requested in the order opposite to storage).
FeatureMatches DecodeMatches(const MatrixBlob& blob, bool swap, const std::string& owner);
std::vector<uint32_t> EncodeMatches(const FeatureMatches& matches, bool swap);
// The blob of EncodeMatches(matches, false) without a copy: FeatureMatch is
// two uint32 (point2D_idx1, point2D_idx2), the stored row's layout.
const void* MatchesAsStored(const FeatureMatches& matches);

// 3x3 float64 matrices are stored row-major (checked against COLMAP 3.8 and
// pycolmap 4.2.1 databases: x2 ~ H x1 holds only with row-major reading).
std::array<double, 9> EncodeMatrix3d(const Eigen::Matrix3d& matrix);
// A NULL or empty blob reads as zero, as COLMAP does.
Eigen::Matrix3d DecodeMatrix3d(const void* data, size_t num_bytes, const std::string& owner);

// Fixed-size float64 vectors (qvec, tvec): `fallback` when NULL or empty.
template <int N>
Eigen::Matrix<double, N, 1> DecodeVector(const void* data, size_t num_bytes,
                                         const Eigen::Matrix<double, N, 1>& fallback,
                                         const std::string& owner);

}  // namespace colmap
}  // namespace cashash
