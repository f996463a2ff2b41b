#include "cashash/pipeline/spatial_pairs.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <thread>
#include <unordered_set>

#include "cashash/base/pair_id.h"

namespace cashash {
namespace {

// GRS80, COLMAP's GPSTransform default.
constexpr double kSemiMajorAxis = 6378137.0;
constexpr double kFlattening = 1.0 / 298.257222100882711243162837;
constexpr double kDegreesToRadians = 0.0174532925199432954743716805978692718781530857086181640625;

// One neighbour candidate: squared distance, then index (the search's own
// order for equal distances: the smaller index first).
struct Candidate {
  double distance_squared;
  int index;
  bool operator<(const Candidate& other) const {
    return distance_squared != other.distance_squared ? distance_squared < other.distance_squared
                                                      : index < other.index;
  }
};

int ThreadCount(int num_threads, size_t work) {
  const int all = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const int wanted = num_threads > 0 ? num_threads : all;
  return static_cast<int>(std::max<size_t>(1, std::min<size_t>(static_cast<size_t>(wanted), work / 256 + 1)));
}

}  // namespace

std::string SpatialPairingOptions::Check() const {
  if (!(max_distance >= 0) || !std::isfinite(max_distance)) {
    std::ostringstream text;
    text << "--SpatialMatching.max_distance must be >= 0 and finite, got " << max_distance;
    return text.str();
  }
  if (max_num_neighbors <= 0) {
    return "--SpatialMatching.max_num_neighbors must be > 0, got " + std::to_string(max_num_neighbors);
  }
  if (min_num_neighbors < 0) {
    return "--SpatialMatching.min_num_neighbors must be >= 0, got " + std::to_string(min_num_neighbors);
  }
  if (min_num_neighbors > max_num_neighbors) {
    return "--SpatialMatching.min_num_neighbors (" + std::to_string(min_num_neighbors) +
           ") must not exceed --SpatialMatching.max_num_neighbors (" + std::to_string(max_num_neighbors) + ")";
  }
  if (max_distance == 0 && min_num_neighbors == 0) {
    return "--SpatialMatching.max_distance 0 needs --SpatialMatching.min_num_neighbors > 0 (else no image has a "
           "neighbour)";
  }
  return "";
}

Eigen::Vector3d GeodeticToEcef(const Eigen::Vector3d& lat_lon_alt) {
  const double e2 = kFlattening * (2.0 - kFlattening);
  const double lat = lat_lon_alt(0) * kDegreesToRadians;
  const double lon = lat_lon_alt(1) * kDegreesToRadians;
  const double alt = lat_lon_alt(2);
  const double sin_lat = std::sin(lat);
  const double cos_lat = std::cos(lat);
  // Prime vertical radius of curvature.
  const double n = kSemiMajorAxis / std::sqrt(1 - e2 * sin_lat * sin_lat);
  return Eigen::Vector3d((n + alt) * cos_lat * std::cos(lon), (n + alt) * cos_lat * std::sin(lon),
                         (n * (1 - e2) + alt) * sin_lat);
}

bool HasUsablePosition(const PositionPrior& prior, const SpatialPairingOptions& options) {
  return options.ignore_z ? prior.position.head<2>().allFinite() : prior.position.allFinite();
}

std::vector<ImagePair> SpatialPairs(std::vector<PositionPrior> priors, const SpatialPairingOptions& options) {
  // COLMAP indexes the images in id order; equal distances keep that order.
  std::sort(priors.begin(), priors.end(),
            [](const PositionPrior& a, const PositionPrior& b) { return a.image_id < b.image_id; });
  std::vector<image_t> ids;
  std::vector<Eigen::Vector3d> positions;
  for (const PositionPrior& prior : priors) {
    if (!HasUsablePosition(prior, options)) continue;
    Eigen::Vector3d p = prior.position;
    if (options.ignore_z) p(2) = 0;
    if (prior.coordinate_system == PriorCoordinateSystem::kWgs84) p = GeodeticToEcef(p);
    ids.push_back(prior.image_id);
    positions.push_back(p);
  }
  const int n = static_cast<int>(positions.size());
  if (n == 0) return {};
  // Centred before the rounding to float, as COLMAP does for precision with
  // large (ECEF) coordinates.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : positions) mean += p;
  mean /= n;
  std::vector<Eigen::Vector3f> rounded(positions.size());
  for (int i = 0; i < n; ++i) rounded[i] = (positions[i] - mean).cast<float>();

  const int knn = std::min(options.max_num_neighbors + 1, n);
  const double max_distance_squared = static_cast<float>(options.max_distance * options.max_distance);
  std::vector<std::vector<int>> neighbours(positions.size());
  auto search = [&](int begin, int end) {
    std::vector<Candidate> candidates(positions.size());
    for (int i = begin; i < end; ++i) {
      for (int j = 0; j < n; ++j) {
        const Eigen::Vector3d d = (rounded[i] - rounded[j]).cast<double>();
        candidates[j] = {d.squaredNorm(), j};
      }
      std::nth_element(candidates.begin(), candidates.begin() + (knn - 1), candidates.end());
      std::sort(candidates.begin(), candidates.begin() + knn);
      for (int rank = 0; rank < knn; ++rank) {
        // The image itself is skipped but keeps its rank: COLMAP counts it
        // in min_num_neighbors' test.
        if (candidates[rank].index == i) continue;
        if (candidates[rank].distance_squared > max_distance_squared && rank > options.min_num_neighbors) break;
        neighbours[i].push_back(candidates[rank].index);
      }
    }
  };
  const int threads = ThreadCount(options.num_threads, static_cast<size_t>(n));
  std::vector<std::thread> workers;
  for (int t = 1; t < threads; ++t) workers.emplace_back(search, t * n / threads, (t + 1) * n / threads);
  search(0, n / threads);
  for (std::thread& worker : workers) worker.join();

  std::vector<ImagePair> pairs;
  std::unordered_set<pair_t> seen;
  for (int i = 0; i < n; ++i) {
    for (int j : neighbours[i]) {
      if (seen.insert(ImagePairToPairId(ids[i], ids[j])).second) pairs.emplace_back(ids[i], ids[j]);
    }
  }
  return pairs;
}

}  // namespace cashash
