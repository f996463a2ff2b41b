#include "colmap_bridge/image_frames.h"

#include "colmap_bridge/sqlite_statement.h"

namespace cashash {
namespace colmap {
namespace {

// COLMAP's SensorType::CAMERA: frame_data rows of cameras name an image.
constexpr int64_t kCameraSensorType = 0;

}  // namespace

std::unordered_map<image_t, uint32_t> ReadImageFrames(const Database& database) {
  std::unordered_map<image_t, uint32_t> frames;
  if (!database.HasTable("frame_data")) return frames;
  database.UseStatement("SELECT frame_id, data_id FROM frame_data WHERE sensor_type = ?", [&](SqliteStatement& s) {
    s.BindInt64(1, kCameraSensorType);
    while (s.Step()) {
      frames[static_cast<image_t>(s.ColumnInt64(1))] = static_cast<uint32_t>(s.ColumnInt64(0));
    }
  });
  return frames;
}

}  // namespace colmap
}  // namespace cashash
