// libFuzzer target: the decoders of keypoint, descriptor, match and
// geometry blobs, fed a (rows, cols) header taken from the input and the
// rest of the input as the blob. They must accept or throw DatabaseError.
#include <cstdint>
#include <cstring>
#include <string>

#include "colmap_bridge/blob_codec.h"
#include "colmap_bridge/database.h"

using namespace cashash::colmap;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 2 * sizeof(int64_t)) return 0;
  MatrixBlob blob;
  std::memcpy(&blob.rows, data, sizeof(int64_t));
  std::memcpy(&blob.cols, data + sizeof(int64_t), sizeof(int64_t));
  blob.data = data + 2 * sizeof(int64_t);
  blob.num_bytes = size - 2 * sizeof(int64_t);
  const auto expect_error_or_value = [](auto decode) {
    try {
      decode();
    } catch (const DatabaseError&) {
    }
  };
  expect_error_or_value([&] {
    const cashash::Keypoints keypoints = DecodeKeypoints(blob, "keypoints");
    if (keypoints.size() != static_cast<size_t>(blob.rows)) __builtin_trap();
  });
  expect_error_or_value([&] {
    const cashash::FeatureDescriptors d = DecodeSiftDescriptors(blob, "descriptors");
    if (d.rows() != static_cast<size_t>(blob.rows)) __builtin_trap();
  });
  expect_error_or_value([&] {
    const bool swap = (data[0] & 1) != 0;
    const cashash::FeatureMatches matches = DecodeMatches(blob, swap, "matches");
    // Encoding what was decoded must give the blob back.
    const std::vector<uint32_t> values = EncodeMatches(matches, swap);
    if (values.size() * sizeof(uint32_t) != blob.num_bytes) __builtin_trap();
    if (!values.empty() && std::memcmp(values.data(), blob.data, blob.num_bytes) != 0) {
      __builtin_trap();
    }
  });
  expect_error_or_value([&] { DecodeMatrix3d(blob.data, blob.num_bytes, "F"); });
  expect_error_or_value([&] {
    DecodeVector<4>(blob.data, blob.num_bytes, Eigen::Vector4d(1, 0, 0, 0), "qvec");
  });
  return 0;
}
