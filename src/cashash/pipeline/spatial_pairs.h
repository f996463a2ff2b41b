// The pairs of COLMAP's spatial_matcher: each image with a position prior is
// matched with its nearest neighbours by that position, at most
// max_num_neighbors of them and only those within max_distance unless
// min_num_neighbors asks for more. GPS priors (WGS84 latitude, longitude in
// degrees, altitude in metres) are compared in Earth-centred Cartesian
// coordinates (ECEF), as COLMAP does. Pure pair generation: reading the
// priors from a database lives in colmap_bridge/position_priors.h.
#pragma once

#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "cashash/base/types.h"

namespace cashash {

// COLMAP's PosePrior::CoordinateSystem values, as stored in pose_priors.
enum class PriorCoordinateSystem { kUndefined = -1, kWgs84 = 0, kCartesian = 1 };

struct PositionPrior {
  image_t image_id = 0;
  // Not finite where unknown (COLMAP stores NaN).
  Eigen::Vector3d position = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  PriorCoordinateSystem coordinate_system = PriorCoordinateSystem::kUndefined;
};

// COLMAP's SpatialMatching.* options (SpatialPairingOptions of pycolmap),
// with its defaults.
struct SpatialPairingOptions {
  // Compare positions without their height (GPS: at altitude 0).
  bool ignore_z = true;
  int max_num_neighbors = 50;
  // Neighbours matched even beyond max_distance.
  int min_num_neighbors = 0;
  // In the priors' unit; metres for GPS.
  double max_distance = 100;
  // COLMAP 3.8's option for its priors in table images, which carry no
  // coordinate system: 1 reads them as GPS, 0 as Cartesian. The pose_priors
  // of 3.10 and later name their own system and ignore it.
  bool is_gps = true;
  // Threads for the neighbour search, -1 for all cores.
  int num_threads = -1;

  // "" or a message naming the option (--SpatialMatching.name).
  std::string Check() const;
};

// WGS84 latitude and longitude (degrees) and altitude (metres) to ECEF
// metres, on the GRS80 ellipsoid that COLMAP's GPSTransform uses by default
// (its axes are WGS84's to a tenth of a millimetre).
Eigen::Vector3d GeodeticToEcef(const Eigen::Vector3d& lat_lon_alt);

// Whether the prior takes part: its x and y (and z unless ignore_z) are
// finite. COLMAP skips the others.
bool HasUsablePosition(const PositionPrior& prior, const SpatialPairingOptions& options);

// The spatial pairs, as (image, neighbour), each unordered pair once in the
// order COLMAP first generates it. Priors without a usable position are
// skipped; an undefined coordinate system is read as Cartesian (COLMAP
// warns so). Positions are centred on their mean and rounded to float, and
// neighbours ordered by distance then by image id, as COLMAP's exhaustive
// search orders them. The search is exact but sweeps along the axis of
// largest spread, so a street or a flight line costs about
// max_num_neighbors distances per image instead of one per image pair.
std::vector<ImagePair> SpatialPairs(std::vector<PositionPrior> priors, const SpatialPairingOptions& options);

}  // namespace cashash
