// COLMAP's spatial pairs (SpatialPairGenerator of COLMAP 4.x): nearest
// neighbours by position prior within max_distance, at most
// max_num_neighbors, at least min_num_neighbors; GPS priors through ECEF.
#include "cashash/pipeline/spatial_pairs.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <tuple>

#include <gtest/gtest.h>

#include "cashash/base/pair_id.h"
#include "pair_id_sets.h"

namespace cashash {
namespace {

using testing_support::PairIds;
using testing_support::WithinSteps;

PositionPrior Cartesian(image_t image_id, double x, double y = 0, double z = 0) {
  PositionPrior prior;
  prior.image_id = image_id;
  prior.position = Eigen::Vector3d(x, y, z);
  prior.coordinate_system = PriorCoordinateSystem::kCartesian;
  return prior;
}

// Images 1..n along x, one unit apart, with a small irregular offset so
// that no two distances tie.
std::vector<PositionPrior> Line(int n) {
  std::vector<PositionPrior> priors;
  for (int i = 0; i < n; ++i) priors.push_back(Cartesian(static_cast<image_t>(i + 1), i + 0.01 * ((i * 7) % 5)));
  return priors;
}

TEST(SpatialPairs, DefaultsAreColmaps) {
  const SpatialPairingOptions options;
  EXPECT_TRUE(options.ignore_z);
  EXPECT_EQ(options.max_num_neighbors, 50);
  EXPECT_EQ(options.min_num_neighbors, 0);
  EXPECT_EQ(options.max_distance, 100);
  EXPECT_EQ(options.Check(), "");
}

TEST(SpatialPairs, NeighboursWithinMaxDistance) {
  SpatialPairingOptions options;
  options.max_distance = 2.5;
  EXPECT_EQ(PairIds(SpatialPairs(Line(12), options)), WithinSteps(12, 2));
  options.max_distance = 100;  // every image within reach: all pairs
  EXPECT_EQ(PairIds(SpatialPairs(Line(12), options)), WithinSteps(12, 11));
}

TEST(SpatialPairs, AtMostMaxNumNeighbors) {
  SpatialPairingOptions options;
  options.max_num_neighbors = 2;
  const std::vector<ImagePair> pairs = SpatialPairs(Line(10), options);
  // Each image's two nearest: the next and previous one, at the ends two on one side.
  std::set<pair_t> expected = WithinSteps(10, 1);
  expected.insert(ImagePairToPairId(1, 3));
  expected.insert(ImagePairToPairId(8, 10));
  EXPECT_EQ(PairIds(pairs), expected);
}

TEST(SpatialPairs, MinNumNeighborsReachBeyondMaxDistance) {
  SpatialPairingOptions options;
  options.max_distance = 0.1;
  options.min_num_neighbors = 2;
  // Each image's two nearest, however far: both sides, or two on one side at the ends.
  std::set<pair_t> expected = WithinSteps(6, 1);
  expected.insert(ImagePairToPairId(1, 3));
  expected.insert(ImagePairToPairId(4, 6));
  EXPECT_EQ(PairIds(SpatialPairs(Line(6), options)), expected);
  options.min_num_neighbors = 0;
  EXPECT_TRUE(SpatialPairs(Line(6), options).empty());
}

TEST(SpatialPairs, EqualDistancesPreferTheSmallerImageId) {
  // Image 2 in the middle, 1 and 3 equally far; 1 and 3 have nearer
  // neighbours of their own (4 and 5), so only 2's choice pairs it.
  SpatialPairingOptions options;
  options.max_num_neighbors = 1;
  const std::vector<PositionPrior> priors = {Cartesian(3, 1.0), Cartesian(5, 1.5), Cartesian(1, -1.0),
                                             Cartesian(2, 0.0), Cartesian(4, -1.5)};
  EXPECT_EQ(PairIds(SpatialPairs(priors, options)),
            (std::set<pair_t>{ImagePairToPairId(1, 4), ImagePairToPairId(3, 5), ImagePairToPairId(1, 2)}));
}

TEST(SpatialPairs, IgnoreZDropsTheHeight) {
  std::vector<PositionPrior> priors = {Cartesian(1, 0, 0, 0), Cartesian(2, 0, 0, 50), Cartesian(3, 0, 3, 0)};
  SpatialPairingOptions options;
  options.max_distance = 10;
  EXPECT_EQ(PairIds(SpatialPairs(priors, options)), WithinSteps(3, 2));
  options.ignore_z = false;
  EXPECT_EQ(PairIds(SpatialPairs(priors, options)), (std::set<pair_t>{ImagePairToPairId(1, 3)}));
}

TEST(SpatialPairs, PriorsWithoutAFinitePositionAreSkipped) {
  std::vector<PositionPrior> priors = Line(4);
  priors[1].position.x() = std::nan("");
  priors[2].position.z() = std::nan("");  // only z unknown: fine while z is ignored
  SpatialPairingOptions options;
  EXPECT_FALSE(HasUsablePosition(priors[1], options));
  EXPECT_TRUE(HasUsablePosition(priors[2], options));
  EXPECT_EQ(PairIds(SpatialPairs(priors, options)),
            (std::set<pair_t>{ImagePairToPairId(1, 3), ImagePairToPairId(1, 4), ImagePairToPairId(3, 4)}));
  options.ignore_z = false;
  EXPECT_FALSE(HasUsablePosition(priors[2], options));
  EXPECT_EQ(PairIds(SpatialPairs(priors, options)), (std::set<pair_t>{ImagePairToPairId(1, 4)}));
}

TEST(SpatialPairs, GeodeticToEcefOnGrs80) {
  const Eigen::Vector3d equator = GeodeticToEcef(Eigen::Vector3d(0, 0, 0));
  EXPECT_NEAR(equator.x(), 6378137.0, 1e-6);
  EXPECT_NEAR(equator.y(), 0.0, 1e-6);
  EXPECT_NEAR(equator.z(), 0.0, 1e-6);
  // The pole lies at the semi-minor axis b = a (1 - f), plus the altitude.
  const Eigen::Vector3d pole = GeodeticToEcef(Eigen::Vector3d(90, 0, 10));
  EXPECT_NEAR(pole.z(), 6378137.0 * (1 - 1 / 298.257222100882711243162837) + 10, 1e-6);
  EXPECT_NEAR(pole.head<2>().norm(), 0.0, 1e-6);
  const Eigen::Vector3d east = GeodeticToEcef(Eigen::Vector3d(0, 90, 0));
  EXPECT_NEAR(east.y(), 6378137.0, 1e-6);
}

TEST(SpatialPairs, GpsPriorsAreComparedInMetres) {
  // Images 30 m apart along a meridian at 47 degrees north; 1 degree of
  // latitude is about 111.2 km there.
  std::vector<PositionPrior> priors;
  for (int i = 0; i < 6; ++i) {
    PositionPrior prior;
    prior.image_id = static_cast<image_t>(i + 1);
    prior.position = Eigen::Vector3d(47.0 + i * 30.0 / 111200.0, 8.0, 400.0 + 5 * i);
    prior.coordinate_system = PriorCoordinateSystem::kWgs84;
    priors.push_back(prior);
  }
  SpatialPairingOptions options;
  options.max_distance = 65;  // two steps of 30 m, not three
  EXPECT_EQ(PairIds(SpatialPairs(priors, options)), WithinSteps(6, 2));
}

// COLMAP's rule written out the slow way: every distance of every image,
// sorted by (distance, image id position), the image itself counted.
std::set<pair_t> ExhaustiveReference(const std::vector<PositionPrior>& priors, const SpatialPairingOptions& options) {
  std::vector<Eigen::Vector3f> points;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const PositionPrior& prior : priors) mean += prior.position;
  mean /= static_cast<double>(priors.size());
  for (const PositionPrior& prior : priors) points.push_back((prior.position - mean).cast<float>());
  const int n = static_cast<int>(points.size());
  const int knn = std::min(options.max_num_neighbors + 1, n);
  const double max_squared = static_cast<float>(options.max_distance * options.max_distance);
  std::set<pair_t> pairs;
  for (int i = 0; i < n; ++i) {
    std::vector<std::pair<double, int>> all;
    for (int j = 0; j < n; ++j) all.emplace_back((points[i] - points[j]).cast<double>().squaredNorm(), j);
    std::sort(all.begin(), all.end());
    for (int rank = 0; rank < knn; ++rank) {
      if (all[rank].second == i) continue;
      if (all[rank].first > max_squared && rank > options.min_num_neighbors) break;
      pairs.insert(ImagePairToPairId(priors[i].image_id, priors[all[rank].second].image_id));
    }
  }
  return pairs;
}

TEST(SpatialPairs, TheSweepFindsWhatAnExhaustiveSearchFinds) {
  // A lattice (many equal distances) and a random cloud, in 2-D and 3-D.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uniform(-20.0, 20.0);
  for (int layout = 0; layout < 4; ++layout) {
    std::vector<PositionPrior> priors;
    for (int k = 0; k < 300; ++k) {
      const Eigen::Vector3d p = layout < 2 ? Eigen::Vector3d(k % 20, (k / 20) % 15, layout == 1 ? k % 3 : 0)
                                           : Eigen::Vector3d(uniform(rng), uniform(rng), layout == 3 ? uniform(rng) : 0);
      priors.push_back(Cartesian(static_cast<image_t>(k + 1), p.x(), p.y(), p.z()));
    }
    for (const auto& [neighbors, distance, minimum] : {std::make_tuple(5, 100.0, 0), std::make_tuple(12, 2.0, 0),
                                                        std::make_tuple(50, 1.0, 7), std::make_tuple(3, 0.5, 3)}) {
      SpatialPairingOptions options;
      options.ignore_z = false;
      options.max_num_neighbors = neighbors;
      options.max_distance = distance;
      options.min_num_neighbors = minimum;
      EXPECT_EQ(PairIds(SpatialPairs(priors, options)), ExhaustiveReference(priors, options))
          << "layout " << layout << ", " << neighbors << " neighbours within " << distance;
    }
  }
}

TEST(SpatialPairs, CheckNamesTheOption) {
  SpatialPairingOptions options;
  options.max_num_neighbors = 0;
  EXPECT_NE(options.Check().find("--SpatialMatching.max_num_neighbors"), std::string::npos);
  options = SpatialPairingOptions();
  options.max_distance = -1;
  EXPECT_NE(options.Check().find("--SpatialMatching.max_distance"), std::string::npos);
  options = SpatialPairingOptions();
  options.min_num_neighbors = 51;
  EXPECT_NE(options.Check().find("--SpatialMatching.min_num_neighbors"), std::string::npos);
  options = SpatialPairingOptions();
  options.max_distance = 0;
  EXPECT_NE(options.Check().find("--SpatialMatching.min_num_neighbors"), std::string::npos);
  options.min_num_neighbors = 3;
  EXPECT_EQ(options.Check(), "");
}

}  // namespace
}  // namespace cashash
