#include "synthetic/synthetic_street_scene.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <Eigen/Geometry>


namespace cashash {
namespace colmap {
namespace {

constexpr double kCameraSpacing = 1.0;  // street units between consecutive cameras
constexpr double kMinDepth = 8.0;
constexpr double kMaxDepth = 14.0;
// Small irregularities of a hand-held or vehicle capture.
constexpr double kPositionJitter = 0.15;
constexpr double kDepthJitter = 0.3;
constexpr double kYawJitterDegrees = 4.0;
constexpr double kPitchJitterDegrees = 2.0;
constexpr double kRollJitterDegrees = 2.0;

// Stream tags, so that cameras and cells never share random numbers.
constexpr uint64_t kCameraTag = 0x43414d4552410000ULL;
constexpr uint64_t kCellTag = 0x43454c4c00000000ULL;

double Uniform(SplitMix64& rng, double low, double high) {
  return low + (high - low) * (static_cast<double>(rng.Next() >> 11) * 0x1.0p-53);
}

double Radians(double degrees) { return degrees * M_PI / 180.0; }

// Points fill the vertical band the cameras see at the mean depth: nearer
// points run off the top and bottom, farther ones leave a margin, as
// buildings do.
double HalfBandHeight(int image_height, double focal_length) {
  return SyntheticStreetScene::MeanDepth() * 0.5 * image_height / focal_length;
}

}  // namespace

SyntheticStreetScene::SyntheticStreetScene(const SyntheticStreetSceneOptions& options) : options_(options) {
  if (options.num_images < 1) throw std::invalid_argument("synthetic scene: num_images must be >= 1");
  if (options.image_width < 2 || options.image_height < 2) {
    throw std::invalid_argument("synthetic scene: image sizes must be >= 2");
  }
  if (!(options.focal_length > 0)) throw std::invalid_argument("synthetic scene: focal_length must be > 0");
  if (options.points_per_cell < 1) throw std::invalid_argument("synthetic scene: points_per_cell must be >= 1");
  if (options.revisit_images < 0 || options.revisit_images >= options.num_images) {
    throw std::invalid_argument("synthetic scene: revisit_images must be in [0, num_images)");
  }
  // The street extends past the first and last camera by what they see
  // sideways, jitter included.
  const double tan_half_width = 0.5 * options.image_width / options.focal_length +
                                std::tan(Radians(kYawJitterDegrees));
  const double margin = kMaxDepth * tan_half_width + 1.0;
  street_begin_ = -margin;
  const int num_places = options.num_images - options.revisit_images;
  const double street_end = (num_places - 1) * kCameraSpacing + margin;
  num_cells_ = static_cast<int64_t>(std::ceil(street_end - street_begin_));
}

double SyntheticStreetScene::MeanDepth() { return 0.5 * (kMinDepth + kMaxDepth); }

double SyntheticStreetScene::VisibleCellsPerImage(int image_width, int image_height, double focal_length) {
  // Mean over the uniform depth of (stretch of street in view) x (share of
  // the band in view), for a camera without jitter.
  const double tan_w = 0.5 * image_width / focal_length;
  const double tan_h = 0.5 * image_height / focal_length;
  const double half_band = HalfBandHeight(image_height, focal_length);
  constexpr int kSteps = 256;
  double sum = 0;
  for (int i = 0; i < kSteps; ++i) {
    const double z = kMinDepth + (kMaxDepth - kMinDepth) * (i + 0.5) / kSteps;
    sum += 2.0 * z * tan_w * std::min(1.0, z * tan_h / half_band);
  }
  return sum / kSteps;
}

Eigen::Matrix3d SyntheticStreetScene::Rotation(int image_index) const {
  SplitMix64 rng(DeriveSeed(options_.random_seed ^ kCameraTag, static_cast<uint64_t>(image_index)));
  const double yaw = Radians(Uniform(rng, -kYawJitterDegrees, kYawJitterDegrees));
  const double pitch = Radians(Uniform(rng, -kPitchJitterDegrees, kPitchJitterDegrees));
  const double roll = Radians(Uniform(rng, -kRollJitterDegrees, kRollJitterDegrees));
  const Eigen::Matrix3d camera_from_world =
      (Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitX()) *
       Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()))
          .toRotationMatrix();
  return camera_from_world;
}

int SyntheticStreetScene::StreetPlace(int image_index) const {
  const int num_places = options_.num_images - options_.revisit_images;
  return image_index < num_places ? image_index : image_index - num_places;
}

Eigen::Vector3d SyntheticStreetScene::Centre(int image_index) const {
  // A stream of its own, so that changing the rotation jitter keeps centres.
  // The stream is the image's, not its place's: a revisiting image stands
  // near, not exactly at, the pose of the image it returns to.
  SplitMix64 rng(DeriveSeed(options_.random_seed ^ kCameraTag, ~static_cast<uint64_t>(image_index)));
  // One draw a statement: the order of a call's arguments is unspecified, and
  // clang and g++ differ. Depth, then height, then along the street keeps
  // the streets g++ builds have always had.
  const double depth_jitter = Uniform(rng, -kDepthJitter, kDepthJitter);
  const double height_jitter = Uniform(rng, -kPositionJitter, kPositionJitter);
  const double along_jitter = Uniform(rng, -kPositionJitter, kPositionJitter);
  return Eigen::Vector3d(StreetPlace(image_index) * kCameraSpacing + along_jitter, height_jitter, depth_jitter);
}

Eigen::Vector3d SyntheticStreetScene::DrawPoint(int64_t cell, SplitMix64& rng) const {
  Eigen::Vector3d position;
  position.x() = street_begin_ + static_cast<double>(cell) + Uniform(rng, 0.0, 1.0);
  position.y() = Uniform(rng, -1.0, 1.0) * HalfBandHeight(options_.image_height, options_.focal_length);
  position.z() = Uniform(rng, kMinDepth, kMaxDepth);
  return position;
}

int64_t SyntheticStreetScene::CellOf(double x) const {
  const int64_t cell = static_cast<int64_t>(std::floor(x - street_begin_));
  return std::clamp<int64_t>(cell, 0, num_cells_ - 1);
}

Eigen::Vector3d SyntheticStreetScene::Point(uint64_t point_index) const {
  const int64_t cell = static_cast<int64_t>(point_index) / options_.points_per_cell;
  const int64_t index_in_cell = static_cast<int64_t>(point_index) % options_.points_per_cell;
  // One stream per cell: the point is the (index_in_cell + 1)th draw.
  SplitMix64 rng(DeriveSeed(options_.random_seed ^ kCellTag, static_cast<uint64_t>(cell)));
  Eigen::Vector3d position;
  for (int64_t i = 0; i <= index_in_cell; ++i) position = DrawPoint(cell, rng);
  return position;
}

std::vector<PointObservation> SyntheticStreetScene::Observe(int image_index) const {
  const Eigen::Matrix3d R = Rotation(image_index);
  const Eigen::Vector3d C = Centre(image_index);
  const double f = options_.focal_length;
  const double cx = 0.5 * options_.image_width;
  const double cy = 0.5 * options_.image_height;

  // Only the cells within the widest possible view are generated.
  const double reach = kMaxDepth * (0.5 * options_.image_width / f + std::tan(Radians(kYawJitterDegrees)) +
                                    std::tan(Radians(kRollJitterDegrees))) + 2.0;
  const int64_t first = std::max<int64_t>(0, static_cast<int64_t>(std::floor(C.x() - reach - street_begin_)));
  const int64_t last = std::min<int64_t>(num_cells_ - 1, static_cast<int64_t>(std::ceil(C.x() + reach - street_begin_)));

  std::vector<PointObservation> observations;
  for (int64_t cell = first; cell <= last; ++cell) {
    SplitMix64 rng(DeriveSeed(options_.random_seed ^ kCellTag, static_cast<uint64_t>(cell)));
    for (int64_t i = 0; i < options_.points_per_cell; ++i) {
      const Eigen::Vector3d X = DrawPoint(cell, rng);
      const Eigen::Vector3d Xc = R * (X - C);
      if (Xc.z() < 1e-6) continue;
      const double x = f * Xc.x() / Xc.z() + cx;
      const double y = f * Xc.y() / Xc.z() + cy;
      // One pixel of margin, so that keypoint noise keeps them inside.
      if (x < 1.0 || y < 1.0 || x > options_.image_width - 1.0 || y > options_.image_height - 1.0) continue;
      PointObservation observation;
      observation.point_index = static_cast<uint64_t>(cell * options_.points_per_cell + i);
      observation.x = x;
      observation.y = y;
      observation.depth = Xc.z();
      observations.push_back(observation);
    }
  }
  return observations;
}

}  // namespace colmap
}  // namespace cashash
