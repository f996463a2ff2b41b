#include "cashash/pipeline/spatial_pairs.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <unordered_set>

#include "cashash/base/pair_id.h"
#include "cashash/base/parallel_for.h"

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

double SquaredDistance(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  return (a - b).cast<double>().squaredNorm();
}

// Exact k nearest neighbours, ordered by (distance, index) as an exhaustive
// search orders them, found by sweeping outwards along the axis of largest
// spread: once the gap along that axis alone exceeds the k-th distance so
// far, nothing farther along can enter. A street or a flight line then
// costs about k points a query instead of all of them.
class KnnSweep {
 public:
  explicit KnnSweep(const std::vector<Eigen::Vector3f>& points) : points_(points) {
    Eigen::Vector3f low = Eigen::Vector3f::Constant(std::numeric_limits<float>::max());
    Eigen::Vector3f high = -low;
    for (const Eigen::Vector3f& p : points) {
      low = low.cwiseMin(p);
      high = high.cwiseMax(p);
    }
    (high - low).maxCoeff(&axis_);
    order_.resize(points.size());
    for (size_t i = 0; i < order_.size(); ++i) order_[i] = static_cast<int>(i);
    std::sort(order_.begin(), order_.end(), [&](int a, int b) { return points[a](axis_) < points[b](axis_); });
    rank_.resize(points.size());
    for (size_t r = 0; r < order_.size(); ++r) rank_[order_[r]] = static_cast<int>(r);
  }

  // The k nearest points to point `query`, itself included, ascending.
  void Nearest(int query, int k, std::vector<Candidate>* nearest) const {
    std::vector<Candidate>& heap = *nearest;  // a max-heap while searching
    heap.clear();
    const Eigen::Vector3f& q = points_[query];
    auto offer = [&](int index) {
      const Candidate candidate{SquaredDistance(q, points_[index]), index};
      if (static_cast<int>(heap.size()) < k) {
        heap.push_back(candidate);
        std::push_heap(heap.begin(), heap.end());
      } else if (candidate < heap.front()) {
        std::pop_heap(heap.begin(), heap.end());
        heap.back() = candidate;
        std::push_heap(heap.begin(), heap.end());
      }
    };
    // Beyond this gap along the axis a point is strictly farther than the
    // k-th so far (equal distances are still offered: the index decides).
    auto beyond = [&](int index) {
      if (static_cast<int>(heap.size()) < k) return false;
      const double gap = static_cast<double>(q(axis_) - points_[index](axis_));
      return gap * gap > heap.front().distance_squared;
    };
    const int n = static_cast<int>(order_.size());
    for (int r = rank_[query]; r < n && !beyond(order_[r]); ++r) offer(order_[r]);
    for (int r = rank_[query] - 1; r >= 0 && !beyond(order_[r]); --r) offer(order_[r]);
    std::sort_heap(heap.begin(), heap.end());
  }

 private:
  const std::vector<Eigen::Vector3f>& points_;
  Eigen::Index axis_ = 0;
  std::vector<int> order_;  // points by their coordinate on axis_
  std::vector<int> rank_;   // position of each point in order_
};

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
  const KnnSweep sweep(rounded);
  std::vector<std::vector<int>> neighbours(positions.size());
  std::vector<std::vector<Candidate>> scratch(static_cast<size_t>(ResolveNumThreads(options.num_threads)));
  ParallelForWorkers(positions.size(), options.num_threads, [&](size_t i, size_t worker) {
    std::vector<Candidate>& nearest = scratch[worker];
    sweep.Nearest(static_cast<int>(i), knn, &nearest);
    for (int rank = 0; rank < knn; ++rank) {
      // The image itself is skipped but keeps its rank: COLMAP counts it
      // in min_num_neighbors' test.
      if (nearest[rank].index == static_cast<int>(i)) continue;
      if (nearest[rank].distance_squared > max_distance_squared && rank > options.min_num_neighbors) break;
      neighbours[i].push_back(nearest[rank].index);
    }
  });

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
