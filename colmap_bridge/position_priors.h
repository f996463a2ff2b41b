// The position priors of a database's images, from where each schema keeps
// them: table pose_priors (COLMAP 3.10 and later, its 4.0 form with
// corr_data_id or the earlier one keyed by image_id), or the prior_tx,
// prior_ty, prior_tz columns of table images (COLMAP 3.8).
#pragma once

#include <string>
#include <vector>

#include "cashash/pipeline/spatial_pairs.h"
#include "colmap_bridge/database.h"

namespace cashash {
namespace colmap {

struct DatabasePositionPriors {
  // One per image that has a prior; images without one have no entry.
  std::vector<PositionPrior> priors;
  // Where they were read, for messages: "table pose_priors" or "columns
  // prior_tx, prior_ty, prior_tz of table images".
  std::string source;
};

// Reads the priors. 3.8's columns carry no coordinate system: `options.is_gps`
// gives it, and, as COLMAP 3.8 reads them, NULL or a zero x and y (and z,
// unless options.ignore_z) mean no prior. Throws DatabaseError naming the
// image for a position blob that is not 3 float64 values, and for an image
// with two priors.
DatabasePositionPriors ReadPositionPriors(const Database& database, const SpatialPairingOptions& options);

// Writes an image's position prior where the schema keeps it: a row of
// pose_priors (4.x: the camera `camera_id` of image `image_id`, covariance
// and gravity unknown; 3.10 to 3.13: keyed by image id), else the prior_tx,
// prior_ty, prior_tz columns of table images (3.8, which keep no
// coordinate system). Replaces an earlier prior of the image.
void WritePositionPrior(Database& database, image_t image_id, camera_t camera_id, const PositionPrior& prior);

}  // namespace colmap
}  // namespace cashash
