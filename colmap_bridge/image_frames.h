// The rig frame of each image, from table frame_data (COLMAP 3.12 and
// later), for sequential matching's expand_rig_images.
#pragma once

#include <unordered_map>

#include "cashash/base/types.h"
#include "colmap_bridge/database.h"

namespace cashash {
namespace colmap {

// Image id to frame id for the camera sensors of table frame_data; empty
// where the database has no such table (COLMAP 3.8).
std::unordered_map<image_t, uint32_t> ReadImageFrames(const Database& database);

}  // namespace colmap
}  // namespace cashash
