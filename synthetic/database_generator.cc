#include "synthetic/database_generator.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <future>
#include <iomanip>
#include <map>
#include <memory>
#include <numeric>
#include <stdexcept>
#include <vector>

#include <Eigen/Geometry>

#include "cashash/matchers/exact_matcher.h"
#include "cashash/geometry/random_sampler.h"
#include "cashash/base/parallel_for.h"
#include "colmap_bridge/colmap38_schema.h"
#include "colmap_bridge/database.h"
#include "colmap_bridge/position_priors.h"
#include "synthetic/sift_descriptor_variation.h"
#include "synthetic/synthetic_street_scene.h"

namespace cashash {
namespace colmap {
namespace {

// At most this many source descriptors are kept (128 MiB); a COLMAP feature
// database of a few dozen photographs holds fewer.
constexpr size_t kMaxPoolDescriptors = size_t{1} << 20;
// Parts each source image is split into when looking for look-alikes.
constexpr size_t kPartsPerSourceImage = 2;
// Images see a little more than planned on average, so that few fall short.
constexpr double kPointHeadroom = 1.15;
// Per-feature descriptor noise, as shares of --descriptor_noise.
constexpr double kMinNoiseShare = 0.25;
constexpr double kMaxNoiseShare = 1.5;
constexpr int kSimplePinholeModel = 0;
constexpr int kPinholeModel = 1;
constexpr int kSimpleRadialModel = 2;
constexpr uint64_t kImageTag = 0x494d414745000000ULL;
constexpr uint64_t kPointDescriptorTag = 0x504f494e54000000ULL;
constexpr uint64_t kStretchTag = 0x5354524554434800ULL;
constexpr uint64_t kFeatureCountTag = 0x434f554e54000000ULL;
// Cells (street units) that share one descriptor order: about what an image
// sees, so that images that see nothing in common rarely share an order.
constexpr int64_t kCellsPerStretch = 12;

// Real descriptors with the affine shape of their keypoints.
struct SourcePool {
  std::vector<uint8_t> descriptors;          // size() x 128
  std::vector<std::array<float, 4>> shapes;  // a11, a12, a21, a22
  int keypoint_columns = 6;
  size_t num_source_images = 0;
  size_t num_source_descriptors = 0;  // before repeated views were left out
  size_t size() const { return shapes.size(); }
  const uint8_t* descriptor(size_t i) const { return descriptors.data() + i * kDescriptorDim; }
};

// Marks the descriptors of later sets that match one of an earlier set. A
// real database sees many points in several photographs, and one photograph
// of a building holds many alike windows and bricks: left in the pool, those
// would make unrelated generated images match each other far more often than
// unrelated photographs do.
std::vector<std::vector<bool>> RepeatedViews(const std::vector<FeatureDescriptors>& images) {
  std::vector<const FeatureDescriptors*> pointers;
  for (const FeatureDescriptors& d : images) pointers.push_back(&d);
  SiftMatchingOptions sift;
  sift.num_threads = -1;
  // Pinned rather than the library defaults, so that a change of defaults
  // does not change what a seed generates (the matcher's code still may).
  CasHashOptions cashash;
  cashash.matcher = MatcherType::kCascade;
  cashash.num_tables = 8;
  cashash.bits_per_table = 7;
  cashash.tau = 40;
  cashash.top_k = 10;
  cashash.random_seed = 0;
  cashash.exact_rematch_min_matches = 0;  // no rematch: the cascade's matches mark the views
  std::unique_ptr<FeatureMatcher> matcher = CreateCpuFeatureMatcher(sift, cashash, ComputeMeanDescriptor(pointers));
  std::vector<ImagePair> pairs;
  for (size_t i = 0; i < images.size(); ++i) {
    matcher->AddImage(static_cast<image_t>(i), images[i]);
    for (size_t j = i + 1; j < images.size(); ++j) pairs.emplace_back(static_cast<image_t>(i), static_cast<image_t>(j));
  }
  std::vector<std::vector<bool>> repeated(images.size());
  for (size_t i = 0; i < images.size(); ++i) repeated[i].assign(images[i].rows(), false);
  const std::vector<FeatureMatches> matches = matcher->Match(pairs);
  for (size_t p = 0; p < pairs.size(); ++p) {
    for (const FeatureMatch& m : matches[p]) repeated[pairs[p].second][m.point2D_idx2] = true;
  }
  return repeated;
}

SourcePool LoadSourcePool(const std::string& path, int max_images) {
  SourcePool pool;
  try {
    const Database source(path, /*read_only=*/true);
    std::vector<Image> images;
    for (const Image& image : source.ReadAllImages()) {
      if (source.NumDescriptors(image.image_id) > 0) images.push_back(image);
    }
    // An even spread over the source when it has more images than we use.
    const size_t count = std::min(images.size(), static_cast<size_t>(max_images));
    std::vector<Keypoints> keypoints(count);
    std::vector<FeatureDescriptors> descriptors(count);
    for (size_t k = 0; k < count; ++k) {
      const Image& image = images[k * images.size() / count];
      keypoints[k] = source.ReadKeypoints(image.image_id);
      descriptors[k] = source.ReadDescriptors(image.image_id);
      if (keypoints[k].size() != descriptors[k].rows()) {
        throw DatabaseError("image " + std::to_string(image.image_id) + " (" + image.name + ") has " +
                            std::to_string(keypoints[k].size()) + " keypoints but " +
                            std::to_string(descriptors[k].rows()) + " descriptors");
      }
      if (k == 0) pool.keypoint_columns = source.KeypointColumns(image.image_id);
    }
    pool.num_source_images = count;
    // Each image is split in parts (row i into part i % parts), so that
    // look-alikes within one photograph are found too.
    std::vector<FeatureDescriptors> parts(count * kPartsPerSourceImage);
    for (size_t k = 0; k < count; ++k) {
      for (size_t i = 0; i < descriptors[k].rows(); ++i) {
        std::vector<uint8_t>& part = parts[k * kPartsPerSourceImage + i % kPartsPerSourceImage].data;
        part.insert(part.end(), descriptors[k].row(i), descriptors[k].row(i) + kDescriptorDim);
      }
    }
    const std::vector<std::vector<bool>> repeated = RepeatedViews(parts);
    for (size_t k = 0; k < count && pool.size() < kMaxPoolDescriptors; ++k) {
      pool.num_source_descriptors += keypoints[k].size();
      for (size_t i = 0; i < keypoints[k].size() && pool.size() < kMaxPoolDescriptors; ++i) {
        if (repeated[k * kPartsPerSourceImage + i % kPartsPerSourceImage][i / kPartsPerSourceImage]) continue;
        const uint8_t* row = descriptors[k].row(i);
        pool.descriptors.insert(pool.descriptors.end(), row, row + kDescriptorDim);
        pool.shapes.push_back({keypoints[k][i].a11, keypoints[k][i].a12, keypoints[k][i].a21, keypoints[k][i].a22});
      }
    }
  } catch (const std::exception& e) {
    throw std::runtime_error("--source_database_path: " + std::string(e.what()));
  }
  if (pool.size() < 2) {
    throw std::runtime_error("--source_database_path " + path + " holds " + std::to_string(pool.size()) +
                             " usable SIFT descriptors; extract features first");
  }
  return pool;
}

// Which real descriptor a 3D point carries. Points are numbered along the
// street; every run of pool-size consecutive points uses each source
// descriptor once, in an order of its own, so that a stretch of street never
// holds two points with the same descriptor.
class PointDescriptors {
 public:
  PointDescriptors(size_t pool_size, uint64_t seed) : pool_size_(pool_size), seed_(seed) {}

  size_t Of(uint64_t point_index) const {
    const uint64_t round = point_index / pool_size_;
    const uint64_t position = point_index % pool_size_;
    SplitMix64 rng(DeriveSeed(seed_ ^ kPointDescriptorTag, round));
    // position -> (a * position + b) mod n is a permutation when gcd(a, n) = 1.
    uint64_t a = 0;
    do {
      a = 1 + rng.Next() % (pool_size_ - 1);  // the pool holds at least 2
    } while (std::gcd(a, static_cast<uint64_t>(pool_size_)) != 1);
    const uint64_t b = rng.Next() % pool_size_;
    return static_cast<size_t>((static_cast<unsigned __int128>(a) * position + b) % pool_size_);
  }

 private:
  size_t pool_size_;
  uint64_t seed_;
};

// The descriptor order of each stretch of street (see
// RandomDescriptorPermutation), made on demand: an image touches two or three.
class StretchPermutations {
 public:
  explicit StretchPermutations(uint64_t seed) : seed_(seed) {}
  const DescriptorPermutation& OfCell(int64_t cell) {
    const int64_t stretch = cell / kCellsPerStretch;
    auto it = cache_.find(stretch);
    if (it == cache_.end()) {
      it = cache_.emplace(stretch, RandomDescriptorPermutation(DeriveSeed(seed_ ^ kStretchTag, static_cast<uint64_t>(stretch)))).first;
    }
    return it->second;
  }

 private:
  uint64_t seed_;
  std::map<int64_t, DescriptorPermutation> cache_;
};

double UniformUnit(SplitMix64& rng) { return static_cast<double>(rng.Next() >> 11) * 0x1.0p-53; }

double Gaussian(SplitMix64& rng) {
  // Box-Muller; 1 - u keeps the logarithm finite.
  const double u = 1.0 - UniformUnit(rng);
  const double v = UniformUnit(rng);
  return std::sqrt(-2.0 * std::log(u)) * std::cos(2.0 * M_PI * v);
}

int CameraModelId(const std::string& name) {
  if (name == "SIMPLE_RADIAL") return kSimpleRadialModel;
  if (name == "PINHOLE") return kPinholeModel;
  if (name == "SIMPLE_PINHOLE") return kSimplePinholeModel;
  return -1;
}

Camera MakeCamera(const DatabaseGeneratorOptions& options, double focal_length) {
  Camera camera;
  camera.model_id = CameraModelId(options.camera_model);
  camera.width = static_cast<uint64_t>(options.image_width);
  camera.height = static_cast<uint64_t>(options.image_height);
  const double cx = 0.5 * options.image_width;
  const double cy = 0.5 * options.image_height;
  switch (camera.model_id) {
    case kPinholeModel:
      camera.params = {focal_length, focal_length, cx, cy};
      break;
    case kSimpleRadialModel:
      camera.params = {focal_length, cx, cy, 0.0};
      break;
    default:
      camera.params = {focal_length, cx, cy};
      break;
  }
  camera.has_prior_focal_length = true;  // as if read from EXIF
  return camera;
}

std::string ImageName(int image_index, int num_images) {
  const int digits = std::max(6, static_cast<int>(std::to_string(num_images).size()));
  std::string number = std::to_string(image_index + 1);
  return "synthetic_" + std::string(digits - number.size(), '0') + number + ".jpg";
}

struct GeneratedImage {
  Keypoints keypoints;
  FeatureDescriptors descriptors;
  size_t observed = 0;  // features that are 3D points
  size_t planned = 0;   // 3D points it was meant to see
};

class ImageGenerator {
 public:
  ImageGenerator(const DatabaseGeneratorOptions& options, const SourcePool& pool,
                 const SyntheticStreetScene& scene)
      : options_(options),
        pool_(pool),
        scene_(scene),
        point_descriptors_(pool.size(), options.random_seed) {}

  GeneratedImage Generate(int image_index) const {
    SplitMix64 rng(DeriveSeed(options_.random_seed ^ kImageTag, static_cast<uint64_t>(image_index)));
    const size_t n = static_cast<size_t>(FeatureCountOfImage(options_, image_index));
    const size_t planned_points = static_cast<size_t>(std::llround(n * (1.0 - options_.distractor_ratio)));
    std::vector<PointObservation> seen = scene_.Observe(image_index);
    // A detector does not fire on every point in view: keep a random subset.
    if (seen.size() > planned_points) {
      for (size_t i = 0; i < planned_points; ++i) {
        std::swap(seen[i], seen[i + rng.Below(static_cast<uint32_t>(seen.size() - i))]);
      }
      seen.resize(planned_points);
    }
    // Features are stored in a random order: rows say nothing about points.
    std::vector<uint32_t> slots(n);
    std::iota(slots.begin(), slots.end(), 0u);
    for (size_t i = n; i > 1; --i) std::swap(slots[i - 1], slots[rng.Below(static_cast<uint32_t>(i))]);

    GeneratedImage image;
    image.observed = seen.size();
    image.planned = planned_points;
    image.keypoints.resize(n);
    image.descriptors.data.resize(n * kDescriptorDim);
    StretchPermutations permutations(options_.random_seed);
    const int64_t camera_cell = scene_.CellOf(scene_.Centre(image_index).x());
    for (size_t i = 0; i < n; ++i) {
      size_t pool_index = 0;
      int64_t cell = camera_cell;
      double x = 0, y = 0, scale = 1;
      if (i < seen.size()) {
        pool_index = point_descriptors_.Of(seen[i].point_index);
        cell = scene_.CellOfPoint(seen[i].point_index);
        x = seen[i].x + options_.keypoint_noise * Gaussian(rng);
        y = seen[i].y + options_.keypoint_noise * Gaussian(rng);
        // Nearer points look larger.
        scale = SyntheticStreetScene::MeanDepth() / seen[i].depth;
      } else {
        // Clutter: a real descriptor at a random place.
        pool_index = rng.Below(static_cast<uint32_t>(pool_.size()));
        x = options_.image_width * UniformUnit(rng);
        y = options_.image_height * UniformUnit(rng);
      }
      Keypoint& kp = image.keypoints[slots[i]];
      kp.x = static_cast<float>(std::clamp(x, 0.0, static_cast<double>(options_.image_width)));
      kp.y = static_cast<float>(std::clamp(y, 0.0, static_cast<double>(options_.image_height)));
      const std::array<float, 4>& shape = pool_.shapes[pool_index];
      kp.a11 = static_cast<float>(shape[0] * scale);
      kp.a12 = static_cast<float>(shape[1] * scale);
      kp.a21 = static_cast<float>(shape[2] * scale);
      kp.a22 = static_cast<float>(shape[3] * scale);
      // Some views of a point change its descriptor little, others a lot:
      // a spread like that of real matches (angles of about 0.1 to 0.35).
      const double sigma =
          options_.descriptor_noise * (kMinNoiseShare + (kMaxNoiseShare - kMinNoiseShare) * UniformUnit(rng));
      PerturbSiftDescriptor(pool_.descriptor(pool_index), permutations.OfCell(cell), sigma, rng,
                            image.descriptors.data.data() + static_cast<size_t>(slots[i]) * kDescriptorDim);
    }
    return image;
  }

 private:
  const DatabaseGeneratorOptions& options_;
  const SourcePool& pool_;
  const SyntheticStreetScene& scene_;
  PointDescriptors point_descriptors_;
};

const char* ModelName(int model_id) {
  switch (model_id) {
    case kPinholeModel: return "PINHOLE";
    case kSimpleRadialModel: return "SIMPLE_RADIAL";
    default: return "SIMPLE_PINHOLE";
  }
}

// The true cameras in COLMAP's text model format (world-to-camera poses).
void WriteGroundTruth(const DatabaseGeneratorOptions& options, const SyntheticStreetScene& scene,
                      const Camera& camera) {
  std::error_code error;
  std::filesystem::create_directories(options.ground_truth_path, error);
  const std::filesystem::path dir(options.ground_truth_path);
  std::ofstream cameras(dir / "cameras.txt"), images(dir / "images.txt"), points(dir / "points3D.txt");
  if (!cameras || !images || !points) {
    throw std::runtime_error("--ground_truth_path: cannot write files in " + options.ground_truth_path);
  }
  cameras << "# CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]\n" << std::setprecision(17);
  images << "# IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME (world-to-camera), then an empty line\n"
         << std::setprecision(17);
  points << "# no points: the ground truth holds cameras only\n";
  for (int k = 0; k < options.num_images; ++k) {
    // Ids as the database assigns them: image k + 1 with its own camera k + 1.
    cameras << k + 1 << " " << ModelName(camera.model_id) << " " << camera.width << " " << camera.height;
    for (double p : camera.params) cameras << " " << p;
    cameras << "\n";
    const Eigen::Matrix3d R = scene.Rotation(k);
    const Eigen::Quaterniond q(R);
    const Eigen::Vector3d t = -R * scene.Centre(k);
    images << k + 1 << " " << q.w() << " " << q.x() << " " << q.y() << " " << q.z() << " " << t.x() << " " << t.y()
           << " " << t.z() << " " << k + 1 << " " << ImageName(k, options.num_images) << "\n\n";
  }
}

void RemoveDatabaseFiles(const std::string& path) {
  std::error_code ignored;
  for (const char* suffix : {"", "-journal", "-wal", "-shm"}) std::filesystem::remove(path + suffix, ignored);
}

bool Finite(double value) { return std::isfinite(value); }

// Where the "gps" street lies: latitude, longitude (degrees), altitude (m).
constexpr double kGpsOriginLatitude = 47.3769;
constexpr double kGpsOriginLongitude = 8.5417;
constexpr double kGpsOriginAltitude = 408.0;
constexpr double kEarthRadius = 6378137.0;  // metres; a sphere is close enough for a few km

// The true centre of image k as --position_priors asks: scene x along the
// street is east, its depth axis z north, and its y (down) the negated
// height.
PositionPrior PriorOfImage(const SyntheticStreetScene& scene, int image_index, const std::string& kind) {
  const Eigen::Vector3d centre = scene.Centre(image_index);
  const Eigen::Vector3d enu(centre.x(), centre.z(), -centre.y());
  PositionPrior prior;
  if (kind == "gps") {
    const double lat0 = kGpsOriginLatitude * M_PI / 180.0;
    prior.position = Eigen::Vector3d(kGpsOriginLatitude + enu.y() / kEarthRadius * 180.0 / M_PI,
                                     kGpsOriginLongitude + enu.x() / (kEarthRadius * std::cos(lat0)) * 180.0 / M_PI,
                                     kGpsOriginAltitude + enu.z());
    prior.coordinate_system = PriorCoordinateSystem::kWgs84;
  } else {
    prior.position = enu;
    prior.coordinate_system = PriorCoordinateSystem::kCartesian;
  }
  return prior;
}

}  // namespace

int FeatureCountOfImage(const DatabaseGeneratorOptions& options, int image_index) {
  if (options.num_features_distribution != "extraction") return options.num_features;
  const int low = options.min_num_features > 0 ? options.min_num_features : std::max(1, options.num_features / 8);
  SplitMix64 rng(DeriveSeed(options.random_seed ^ kFeatureCountTag, static_cast<uint64_t>(image_index)));
  if (UniformUnit(rng) < options.num_features_at_cap_share || low >= options.num_features) {
    return options.num_features;
  }
  return low + static_cast<int>(rng.Below(static_cast<uint32_t>(options.num_features - low)));
}

namespace {

// Each Check* below returns the first problem of one group of
// DatabaseGeneratorOptions, "" when there is none.

std::string CheckGeneratorPaths(const DatabaseGeneratorOptions& o) {
  if (o.database_path.empty()) return "--database_path is required";
  if (o.source_database_path.empty()) return "--source_database_path is required";
  if (std::filesystem::path(o.database_path).lexically_normal() ==
      std::filesystem::path(o.source_database_path).lexically_normal()) {
    return "--database_path must differ from --source_database_path (the source is only read)";
  }
  return "";
}

std::string CheckGeneratorCounts(const DatabaseGeneratorOptions& o) {
  if (o.num_images < 1 || o.num_images > 2147483646) return "--num_images must be between 1 and 2147483646";
  if (o.revisit_images < 0 || o.revisit_images >= o.num_images) {
    return "--revisit_images must be between 0 and --num_images - 1 (" + std::to_string(o.num_images - 1) + "), got " +
           std::to_string(o.revisit_images);
  }
  if (o.num_features < 1 || o.num_features > (1 << 24)) return "--num_features must be between 1 and 16777216";
  if (o.num_features_distribution != "equal" && o.num_features_distribution != "extraction") {
    return "--num_features_distribution must be equal or extraction, got '" + o.num_features_distribution + "'";
  }
  if (o.min_num_features < 0 || o.min_num_features > o.num_features) {
    return "--min_num_features must be between 0 (num_features / 8) and --num_features";
  }
  if (!Finite(o.num_features_at_cap_share) || o.num_features_at_cap_share < 0 || o.num_features_at_cap_share > 1) {
    return "--num_features_at_cap_share must be between 0 and 1";
  }
  if (o.num_points < 0) return "--num_points must be >= 0 (0 = as many as the images need)";
  return "";
}

std::string CheckGeneratorCamera(const DatabaseGeneratorOptions& o) {
  if (o.image_width < 16 || o.image_height < 16 || o.image_width > 100000 || o.image_height > 100000) {
    return "--image_width and --image_height must be between 16 and 100000";
  }
  if (CameraModelId(o.camera_model) < 0) {
    return "--camera_model must be SIMPLE_RADIAL, PINHOLE or SIMPLE_PINHOLE, got '" + o.camera_model + "'";
  }
  if (!Finite(o.focal_length_factor) || o.focal_length_factor <= 0.1 || o.focal_length_factor > 100) {
    return "--focal_length_factor must be between 0.1 and 100";
  }
  return "";
}

std::string CheckGeneratorNoise(const DatabaseGeneratorOptions& o) {
  if (!Finite(o.distractor_ratio) || o.distractor_ratio < 0 || o.distractor_ratio > 1) {
    return "--distractor_ratio must be between 0 and 1";
  }
  if (!Finite(o.keypoint_noise) || o.keypoint_noise < 0 || o.keypoint_noise > 100) {
    return "--keypoint_noise must be between 0 and 100 pixels";
  }
  if (!Finite(o.descriptor_noise) || o.descriptor_noise < 0 || o.descriptor_noise > 255) {
    return "--descriptor_noise must be between 0 and 255";
  }
  return "";
}

std::string CheckGeneratorRun(const DatabaseGeneratorOptions& o) {
  if (o.images_per_transaction < 1) return "--images_per_transaction must be >= 1";
  if (o.position_priors != "none" && o.position_priors != "cartesian" && o.position_priors != "gps") {
    return "--position_priors must be none, cartesian or gps, got '" + o.position_priors + "'";
  }
  if (o.num_threads == 0 || o.num_threads < -1) return "--num_threads must be -1 (all cores) or at least 1";
  if (o.source_max_images < 1 || o.source_max_images > 1000) return "--source_max_images must be between 1 and 1000";
  return "";
}

}  // namespace

std::string DatabaseGeneratorOptions::Check() const {
  for (auto check : {CheckGeneratorPaths, CheckGeneratorCounts, CheckGeneratorCamera, CheckGeneratorNoise,
                     CheckGeneratorRun}) {
    std::string problem = check(*this);
    if (!problem.empty()) return problem;
  }
  return "";
}

// One function because the pipelined write loop (batch t + 1 made on a future
// while batch t is written) and its catch, which must wait for that future
// before removing the file, share the scene, generator and database locals.
GeneratorSummary GenerateDatabase(const DatabaseGeneratorOptions& options,
                                  const std::function<void(const GeneratorProgress&)>& progress) {
  const std::string problem = options.Check();
  if (!problem.empty()) throw std::invalid_argument(problem);
  std::error_code error;
  if (std::filesystem::exists(options.database_path, error)) {
    throw std::invalid_argument("--database_path " + options.database_path +
                                " exists already; generate_database writes a new database (remove the file first)");
  }
  using Clock = std::chrono::steady_clock;
  const Clock::time_point start = Clock::now();

  const SourcePool pool = LoadSourcePool(options.source_database_path, options.source_max_images);

  SyntheticStreetSceneOptions scene_options;
  scene_options.num_images = options.num_images;
  scene_options.image_width = options.image_width;
  scene_options.image_height = options.image_height;
  scene_options.focal_length = options.focal_length_factor * std::max(options.image_width, options.image_height);
  scene_options.random_seed = options.random_seed;
  scene_options.revisit_images = options.revisit_images;
  scene_options.points_per_cell = 1;
  const int64_t num_cells = SyntheticStreetScene(scene_options).num_cells();
  if (options.num_points > 0) {
    scene_options.points_per_cell = std::max<int64_t>(1, std::llround(static_cast<double>(options.num_points) / num_cells));
  } else {
    const double planned = options.num_features * (1.0 - options.distractor_ratio);
    const double cells_in_view = SyntheticStreetScene::VisibleCellsPerImage(
        options.image_width, options.image_height, scene_options.focal_length);
    scene_options.points_per_cell = std::max<int64_t>(1, std::llround(kPointHeadroom * planned / cells_in_view));
  }
  const SyntheticStreetScene scene(scene_options);
  const ImageGenerator generator(options, pool, scene);
  const Camera camera = MakeCamera(options, scene_options.focal_length);

  GeneratorSummary summary;
  summary.num_scene_points = scene.num_points();
  summary.keypoint_columns = pool.keypoint_columns;
  summary.source_images = pool.num_source_images;
  summary.source_descriptors = pool.num_source_descriptors;
  summary.pool_descriptors = pool.size();

  CreateColmap38Database(options.database_path);
  // Images of transaction t + 1 are made on the worker threads while this
  // thread writes those of transaction t.
  auto make_batch = [&](int first) {
    const int end = std::min(options.num_images, first + options.images_per_transaction);
    std::vector<GeneratedImage> batch(static_cast<size_t>(std::max(0, end - first)));
    ParallelFor(batch.size(), options.num_threads,
                [&](size_t i) { batch[i] = generator.Generate(first + static_cast<int>(i)); });
    return batch;
  };
  std::future<std::vector<GeneratedImage>> next;
  try {
    Database database(options.database_path);
    next = std::async(std::launch::async, make_batch, 0);
    for (int first = 0; first < options.num_images; first += options.images_per_transaction) {
      const int end = std::min(options.num_images, first + options.images_per_transaction);
      const std::vector<GeneratedImage> batch = next.get();
      if (end < options.num_images) next = std::async(std::launch::async, make_batch, end);
      database.BeginTransaction();
      for (int k = first; k < end; ++k) {
        const GeneratedImage& image = batch[static_cast<size_t>(k - first)];
        const camera_t camera_id = database.WriteCamera(camera);
        const image_t image_id = database.WriteImage(ImageName(k, options.num_images), camera_id);
        if (options.position_priors != "none") {
          WritePositionPrior(database, image_id, camera_id, PriorOfImage(scene, k, options.position_priors));
        }
        database.WriteKeypoints(image_id, image.keypoints, pool.keypoint_columns);
        database.WriteDescriptors(image_id, image.descriptors);
        summary.num_features += static_cast<int64_t>(image.keypoints.size());
        summary.observed_features += static_cast<int64_t>(image.observed);
        if (image.observed < image.planned) ++summary.images_short_of_points;
        summary.min_features = k == 0 ? image.keypoints.size() : std::min(summary.min_features, image.keypoints.size());
        summary.max_features = std::max(summary.max_features, image.keypoints.size());
      }
      database.Commit();
      summary.num_images = end;
      if (progress) {
        GeneratorProgress p;
        p.images_done = end;
        p.images_total = options.num_images;
        p.elapsed_seconds = std::chrono::duration<double>(Clock::now() - start).count();
        progress(p);
      }
    }
  } catch (...) {
    if (next.valid()) next.wait();  // the workers read the generator
    RemoveDatabaseFiles(options.database_path);
    throw;
  }
  SetWalJournal(options.database_path);
  if (!options.ground_truth_path.empty()) WriteGroundTruth(options, scene, camera);
  summary.file_bytes = std::filesystem::file_size(options.database_path, error);
  summary.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return summary;
}

}  // namespace colmap
}  // namespace cashash
