#include "colmap_bridge/database_pipeline_io.h"

namespace cashash {
namespace colmap {

DatabaseFeatureSource::DatabaseFeatureSource(const std::string& database_path)
    : database_(database_path, /*read_only=*/true) {
  images_ = database_.ReadAllImages();
  for (Camera& camera : database_.ReadAllCameras()) cameras_.emplace(camera.camera_id, std::move(camera));
  for (size_t i = 0; i < images_.size(); ++i) {
    image_index_.emplace(images_[i].image_id, i);
    if (!cameras_.count(images_[i].camera_id)) {
      throw DatabaseError("table images: image " + std::to_string(images_[i].image_id) + " (" + images_[i].name +
                          ") refers to camera " + std::to_string(images_[i].camera_id) +
                          ", which is not in table cameras");
    }
  }
}

const Image& DatabaseFeatureSource::image(image_t image_id) const { return images_.at(image_index_.at(image_id)); }

ImageFeatures DatabaseFeatureSource::LoadFeatures(image_t image_id) {
  ImageFeatures features;
  features.image_id = image_id;
  features.keypoints = database_.ReadKeypoints(image_id);
  features.descriptors = database_.ReadDescriptors(image_id);
  if (features.keypoints.size() != features.descriptors.rows()) {
    const Image& im = image(image_id);
    throw DatabaseError("image " + std::to_string(image_id) + " (" + im.name + "): table keypoints has " +
                        std::to_string(features.keypoints.size()) + " rows but table descriptors has " +
                        std::to_string(features.descriptors.rows()));
  }
  return features;
}

const Camera& DatabaseFeatureSource::CameraOfImage(image_t image_id) const {
  return cameras_.at(image(image_id).camera_id);
}

DatabaseResultSink::DatabaseResultSink(const std::string& database_path, bool write_two_view_geometries)
    : database_(database_path, /*read_only=*/false), write_two_view_geometries_(write_two_view_geometries) {}

void DatabaseResultSink::WriteChunk(const std::vector<PairResult>& results) {
  database_.BeginTransaction();
  try {
    for (const PairResult& result : results) {
      database_.WriteMatches(result.pair.first, result.pair.second, result.matches);
      if (write_two_view_geometries_) {
        database_.WriteTwoViewGeometry(result.pair.first, result.pair.second, result.geometry);
      }
    }
    database_.Commit();
  } catch (...) {
    database_.Rollback();
    throw;
  }
}

}  // namespace colmap
}  // namespace cashash
