// The matching pipeline's source and sink on a COLMAP database: features are
// read through one connection, results written through another in one
// transaction per chunk, so that a stopped run leaves whole chunks only.
#pragma once

#include <string>
#include <unordered_map>
#include <vector>

#include "cashash/matching_pipeline.h"
#include "colmap_bridge/database.h"

namespace cashash {
namespace colmap {

class DatabaseFeatureSource : public FeatureSource {
 public:
  // Reads the images and cameras tables; throws DatabaseError if an image
  // refers to a camera that does not exist.
  explicit DatabaseFeatureSource(const std::string& database_path);

  const std::vector<Image>& images() const { return images_; }
  const Image& image(image_t image_id) const;

  // Throws DatabaseError naming the image when keypoints and descriptors
  // disagree in their number of rows.
  ImageFeatures LoadFeatures(image_t image_id) override;
  const Camera& CameraOfImage(image_t image_id) const override;

  Database& database() { return database_; }

 private:
  Database database_;
  std::vector<Image> images_;
  std::unordered_map<image_t, size_t> image_index_;
  std::unordered_map<camera_t, Camera> cameras_;
};

class DatabaseResultSink : public ResultSink {
 public:
  DatabaseResultSink(const std::string& database_path, bool write_two_view_geometries);
  void WriteChunk(const std::vector<PairResult>& results) override;

 private:
  Database database_;
  bool write_two_view_geometries_;
};

}  // namespace colmap
}  // namespace cashash
