// Writes the raw matches of a matched COLMAP database as a verification
// pairs file (src/cashash/pipeline/verification_pairs_file.h), so verification can be
// benchmarked and tested on machines without the database.
// Usage: dump_verification_pairs DB OUT.bin [min_matches]
#include <cstdlib>
#include <iostream>
#include <unordered_map>

#include "cashash/pipeline/verification_pairs_file.h"
#include "colmap_bridge/database.h"

int main(int argc, char** argv) {
  if (argc < 3) {
    std::cerr << "usage: " << argv[0] << " DB OUT.bin [min_matches]\n";
    return 2;
  }
  const size_t min_matches = argc > 3 ? std::strtoull(argv[3], nullptr, 10) : 0;
  try {
    // Opened read-write: a read-only connection does not prepare the match
    // tables. Nothing is written.
    const cashash::colmap::Database db(argv[1]);
    std::unordered_map<cashash::camera_t, cashash::Camera> cameras;
    for (const cashash::Camera& c : db.ReadAllCameras()) cameras[c.camera_id] = c;
    const std::vector<cashash::Image> images = db.ReadAllImages();
    std::vector<cashash::Keypoints> keypoints;
    for (const cashash::Image& image : images) keypoints.push_back(db.ReadKeypoints(image.image_id));
    std::vector<cashash::StoredVerificationPair> pairs;
    size_t total = 0;
    for (size_t i = 0; i < images.size(); ++i) {
      for (size_t j = i + 1; j < images.size(); ++j) {
        const cashash::FeatureMatches matches = db.ReadMatches(images[i].image_id, images[j].image_id);
        if (matches.empty() || matches.size() < min_matches) continue;
        cashash::StoredVerificationPair p;
        p.pair = {images[i].image_id, images[j].image_id};
        p.camera1 = cameras.at(images[i].camera_id);
        p.camera2 = cameras.at(images[j].camera_id);
        for (const cashash::FeatureMatch& m : matches) {
          const cashash::Keypoint& a = keypoints[i].at(m.point2D_idx1);
          const cashash::Keypoint& b = keypoints[j].at(m.point2D_idx2);
          const auto k = static_cast<cashash::point2D_t>(p.points1.size());
          p.points1.emplace_back(a.x, a.y);
          p.points2.emplace_back(b.x, b.y);
          p.matches.push_back({k, k});
        }
        total += matches.size();
        pairs.push_back(std::move(p));
      }
    }
    cashash::WriteVerificationPairsFile(argv[2], pairs);
    std::cout << "wrote " << pairs.size() << " pairs, " << total << " matches to " << argv[2] << std::endl;
  } catch (const std::exception& e) {
    std::cerr << "ERROR: " << e.what() << std::endl;
    return 1;
  }
  return 0;
}
