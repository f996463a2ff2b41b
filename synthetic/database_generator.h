// `cashash generate_database`: a COLMAP database of any size whose features
// behave like real ones, to measure matching at 5,000 to 20,000 images.
// The geometry is a SyntheticStreetScene; every 3D point carries a real SIFT
// descriptor of the source database (values reordered per stretch of street,
// see RandomDescriptorPermutation), each image observes its points with
// pixel noise and its own descriptor noise, and real descriptors at random
// places fill each image up to exactly num_features (what a detector finds
// on clutter, sky, cars). Images are generated and written one at a time:
// memory does not grow with the number of images.
//
// With revisit_images K > 0 the street returns to its start: the last K
// images drive its first K places again (SyntheticStreetScene), seeing the
// same points with descriptor and keypoint noise of their own, so that a
// sequence ordered along the path has loops to close.
//
// Feature counts: by default every image has num_features. With
// num_features_distribution "extraction" they look like a SIFT extraction
// (COLMAP's feature_extractor, whose --SiftExtraction.max_num_features caps
// every image): a share of the images sits at the cap, num_features, and
// the rest spread evenly between min_num_features and the cap (see
// FeatureCountOfImage). Textured photographs fill the extractor's cap;
// plain walls, sky, blur and small images fall below it, some far below.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

namespace cashash {
namespace colmap {

struct DatabaseGeneratorOptions {
  std::string database_path;         // created; must not exist
  std::string source_database_path;  // COLMAP database with SIFT features
  int num_images = 0;
  // The last revisit_images images return to the start of the street, each
  // near the pose of image k - (num_images - revisit_images); 0 = a street
  // that never comes back (as before: the same database for a seed).
  int revisit_images = 0;
  int num_features = 8192;  // per image: exactly ("equal"), or the cap ("extraction")
  // "equal": every image has num_features. "extraction": a share
  // num_features_at_cap_share of the images has num_features, the others
  // a count drawn evenly from [min_num_features, num_features).
  std::string num_features_distribution = "equal";
  int min_num_features = 0;                // "extraction": 0 = num_features / 8
  double num_features_at_cap_share = 0.4;  // "extraction": images at the cap
  // 3D points of the whole scene; 0 chooses enough for every image to see
  // num_features x (1 - distractor_ratio) of them.
  int64_t num_points = 0;
  uint64_t random_seed = 0;
  int image_width = 1600;
  int image_height = 1200;
  std::string camera_model = "SIMPLE_RADIAL";  // or PINHOLE; focal prior known
  double focal_length_factor = 1.2;  // focal = factor x max(width, height), COLMAP's guess
  double distractor_ratio = 0.3;     // share of features that are no 3D point
  double keypoint_noise = 0.5;       // pixels (standard deviation)
  // Stored uint8 units; each feature draws its own standard deviation
  // between 0.25 and 1.5 times this.
  double descriptor_noise = 8.0;
  int images_per_transaction = 50;
  // Threads that make images (each image has its own seed: the database is
  // the same for any count); one more writes them. -1 = all cores.
  int num_threads = -1;
  // Source images whose descriptors are used (spread evenly over the source).
  // Views of one point in several of them are kept once; finding those costs
  // a matching of every pair of them.
  int source_max_images = 24;
  // Position priors of the images, for spatial matching: "none", "cartesian"
  // (the true camera centres as east, north, up in street units, taken as
  // metres) or "gps" (the same centres as WGS84 latitude, longitude and
  // altitude around kGpsOrigin). This schema (COLMAP 3.8) keeps them in the
  // prior_tx, prior_ty, prior_tz columns of table images.
  std::string position_priors = "none";
  // When set: a folder that receives the true cameras as a COLMAP text model
  // (cameras.txt, images.txt, an empty points3D.txt), for comparing a
  // reconstruction (scripts/summarize_model.py --gt).
  std::string ground_truth_path;

  // "" or a message naming the option at fault (--name as on the command line).
  std::string Check() const;
};

struct GeneratorProgress {
  int images_done = 0;
  int images_total = 0;
  double elapsed_seconds = 0;
};

struct GeneratorSummary {
  int num_images = 0;
  int64_t num_features = 0;      // all images together
  size_t min_features = 0;       // of one image
  size_t max_features = 0;
  int64_t num_scene_points = 0;  // 3D points of the scene
  int64_t observed_features = 0;  // features that are projections of 3D points
  int images_short_of_points = 0;  // saw fewer points than planned (filled up with distractors)
  int keypoint_columns = 6;
  size_t source_images = 0;       // source images read
  size_t source_descriptors = 0;  // their descriptors
  size_t pool_descriptors = 0;    // left after repeated views of a point
  uint64_t file_bytes = 0;
  double seconds = 0;
};

// The features of image `image_index` (0-based) under the options'
// distribution: the same for a seed whatever the threads or the other
// images, drawn from a random stream of its own so that "equal" databases
// stay as they were. Expects checked options.
int FeatureCountOfImage(const DatabaseGeneratorOptions& options, int image_index);

// Throws std::invalid_argument for bad options and std::runtime_error
// (DatabaseError included) for an unusable source or output; a partly
// written output is removed.
GeneratorSummary GenerateDatabase(const DatabaseGeneratorOptions& options,
                                  const std::function<void(const GeneratorProgress&)>& progress = {});

}  // namespace colmap
}  // namespace cashash
