// Test helpers for generated databases: a small source database of random
// SIFT-like descriptors (no COLMAP needed) and a scratch directory.
#pragma once

#include <filesystem>
#include <random>
#include <string>

#include <unistd.h>

#include "colmap_bridge/colmap38_schema.h"
#include "colmap_bridge/database.h"
#include "synthetic_sift.h"

namespace cashash {
namespace testing_support {

// A fresh directory under the system temp dir, removed on destruction.
class ScratchDir {
 public:
  explicit ScratchDir(const std::string& tag) {
    path_ = std::filesystem::temp_directory_path() / ("cashash_" + tag + "_" + std::to_string(getpid()));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~ScratchDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  std::string File(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

// A COLMAP 3.8 database with `num_images` images of `num_features` random
// SIFT-like descriptors and 6-column keypoints, as a generator source.
inline void WriteRandomSourceDatabase(const std::string& path, int num_images, int num_features) {
  colmap::CreateColmap38Database(path);
  colmap::Database db(path);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> position(0.f, 1000.f), scale(1.f, 8.f);
  db.BeginTransaction();
  for (int k = 0; k < num_images; ++k) {
    Camera camera;
    camera.model_id = 1;  // PINHOLE
    camera.width = 1000;
    camera.height = 1000;
    camera.params = {1200, 1200, 500, 500};
    const camera_t camera_id = db.WriteCamera(camera);
    const image_t image_id = db.WriteImage("source_" + std::to_string(k) + ".jpg", camera_id);
    Keypoints keypoints(static_cast<size_t>(num_features));
    FeatureDescriptors descriptors;
    for (Keypoint& kp : keypoints) {
      kp.x = position(rng);
      kp.y = position(rng);
      kp.a11 = kp.a22 = scale(rng);
      const std::vector<uint8_t> d = RandomSift(&rng);
      descriptors.data.insert(descriptors.data.end(), d.begin(), d.end());
    }
    db.WriteKeypoints(image_id, keypoints, 6);
    db.WriteDescriptors(image_id, descriptors);
  }
  db.Commit();
}

}  // namespace testing_support
}  // namespace cashash
