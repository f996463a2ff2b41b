// The geometry behind generate_database: a long street of 3D points seen by
// cameras that drive along it looking sideways, like a street-level capture.
// Camera k stands about k units along the street; the points lie 8 to 14
// units away, so an image sees a stretch about ten units long and shares
// points with roughly its ten nearest neighbours on either side, and none
// with cameras farther away: in a large collection most pairs are empty, as
// in real ones. The depth range (about half the mean depth) keeps pairs away
// from the planar case, so E and F decide them as on real photographs.
//
// Points are laid out in unit-long cells along the street and generated from
// the seed and the cell index alone, so observing an image touches only the
// cells it sees: memory does not grow with the number of images.
//
// With revisit_images K > 0 the street returns to its start: the last K
// images drive its beginning again, image k >= N - K at the place of image
// k - (N - K), so that they see the same cells, hence the same points, as
// the images there, from poses of their own (the usual jitter, drawn for k),
// the way a second drive past the same houses does. They give sequential
// matching loops to close. The street is as long as its N - K places.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "cashash/geometry/random_sampler.h"

namespace cashash {
namespace colmap {

struct SyntheticStreetSceneOptions {
  int num_images = 0;
  int image_width = 1600;
  int image_height = 1200;
  double focal_length = 1920;  // pixels
  int64_t points_per_cell = 0;   // 3D points per unit of street length
  uint64_t random_seed = 0;
  // The last revisit_images images stand at the first places again; in
  // [0, num_images).
  int revisit_images = 0;
};

// One 3D point as seen by one image, before keypoint noise.
struct PointObservation {
  uint64_t point_index = 0;  // stable over images: the same point, the same index
  double x = 0;              // pixel, upper-left pixel centre at (0.5, 0.5)
  double y = 0;
  double depth = 0;  // along the optical axis
};

class SyntheticStreetScene {
 public:
  // Throws std::invalid_argument on non-positive sizes or counts, or a
  // revisit_images outside [0, num_images).
  explicit SyntheticStreetScene(const SyntheticStreetSceneOptions& options);

  int num_images() const { return options_.num_images; }
  int64_t num_cells() const { return num_cells_; }
  int64_t num_points() const { return num_cells_ * options_.points_per_cell; }

  // The place along the street image k (0-based) stands at, in
  // [0, num_images - revisit_images): k, or for the revisiting images the
  // place of the image they return to.
  int StreetPlace(int image_index) const;

  // Pose of image k (0-based): x_camera = R * (x_world - centre). Cameras
  // look along +z with x to the right and y down, as COLMAP's.
  Eigen::Matrix3d Rotation(int image_index) const;
  Eigen::Vector3d Centre(int image_index) const;

  // Position of a point by its index (PointObservation::point_index).
  Eigen::Vector3d Point(uint64_t point_index) const;

  // The cell a street position (x) or a point falls into, in [0, num_cells).
  int64_t CellOf(double x) const;
  int64_t CellOfPoint(uint64_t point_index) const {
    return static_cast<int64_t>(point_index) / options_.points_per_cell;
  }

  // Every point that projects inside image k, in point order.
  std::vector<PointObservation> Observe(int image_index) const;

  // The mean depth of the points, a natural unit for keypoint scales.
  static double MeanDepth();

  // Points an image sees on average per point of a cell: multiplied by
  // points_per_cell it gives the expected visible points of an image.
  static double VisibleCellsPerImage(int image_width, int image_height, double focal_length);

 private:
  // The next point of `cell` from the cell's random stream.
  Eigen::Vector3d DrawPoint(int64_t cell, SplitMix64& rng) const;

  SyntheticStreetSceneOptions options_;
  double street_begin_ = 0;  // x of the first cell
  int64_t num_cells_ = 0;
};

}  // namespace colmap
}  // namespace cashash
