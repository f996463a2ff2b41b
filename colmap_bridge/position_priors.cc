#include "colmap_bridge/position_priors.h"

#include <cstring>
#include <limits>
#include <unordered_set>

#include "colmap_bridge/sqlite_statement.h"

namespace cashash {
namespace colmap {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// COLMAP's SensorType::CAMERA in pose_priors.corr_sensor_type.
constexpr int64_t kCameraSensorType = 0;

std::string ImageText(image_t image_id) { return "image " + std::to_string(image_id); }

// A position blob: 3 float64 values, or NULL (unknown).
Eigen::Vector3d PositionAt(const SqliteStatement& s, int col, image_t image_id) {
  if (s.ColumnIsNull(col)) return Eigen::Vector3d::Constant(kNaN);
  if (s.ColumnBytes(col) != 3 * sizeof(double)) {
    throw DatabaseError("table pose_priors: the position of " + ImageText(image_id) + " has " +
                        std::to_string(s.ColumnBytes(col)) + " bytes, not 3 float64 values (24 bytes)");
  }
  Eigen::Vector3d position;
  std::memcpy(position.data(), s.ColumnBlob(col), 3 * sizeof(double));
  return position;
}

PriorCoordinateSystem CoordinateSystemOf(int64_t value) {
  switch (value) {
    case 0: return PriorCoordinateSystem::kWgs84;
    case 1: return PriorCoordinateSystem::kCartesian;
    default: return PriorCoordinateSystem::kUndefined;
  }
}

void AddUnique(DatabasePositionPriors* out, std::unordered_set<image_t>* seen, const PositionPrior& prior) {
  if (!seen->insert(prior.image_id).second) {
    throw DatabaseError("table pose_priors holds two priors of " + ImageText(prior.image_id));
  }
  out->priors.push_back(prior);
}

// The rows (image id, position blob, coordinate system) of a pose_priors
// query, the first of each image kept.
void AddPriorRows(SqliteStatement& s, DatabasePositionPriors* out) {
  std::unordered_set<image_t> seen;
  while (s.Step()) {
    PositionPrior prior;
    prior.image_id = static_cast<image_t>(s.ColumnInt64(0));
    prior.position = PositionAt(s, 1, prior.image_id);
    prior.coordinate_system = CoordinateSystemOf(s.ColumnInt64(2));
    AddUnique(out, &seen, prior);
  }
}

// COLMAP 4.0 and later: a prior per sensor; those of cameras belong to the
// image corr_data_id.
void ReadPosePriorsOf4x(const Database& database, DatabasePositionPriors* out) {
  database.UseStatement(
      "SELECT corr_data_id, position, coordinate_system FROM pose_priors WHERE corr_sensor_type = ? "
      "ORDER BY corr_data_id",
      [&](SqliteStatement& s) {
        s.BindInt64(1, kCameraSensorType);
        AddPriorRows(s, out);
      });
}

// COLMAP 3.10 to 3.13: one prior per image, keyed by image_id.
void ReadPosePriorsByImage(const Database& database, DatabasePositionPriors* out) {
  database.UseStatement("SELECT image_id, position, coordinate_system FROM pose_priors ORDER BY image_id",
                        [&](SqliteStatement& s) { AddPriorRows(s, out); });
}

// COLMAP 3.8: the prior_t* columns of table images, read as 3.8 reads them.
void ReadImagePriorColumns(const Database& database, const SpatialPairingOptions& options,
                           DatabasePositionPriors* out) {
  database.UseStatement(
      "SELECT image_id, prior_tx, prior_ty, prior_tz FROM images ORDER BY image_id", [&](SqliteStatement& s) {
        while (s.Step()) {
          // NULL reads as 0, as COLMAP 3.8 reads it.
          const double value[3] = {s.ColumnDouble(1), s.ColumnDouble(2), s.ColumnDouble(3)};
          const bool no_xy = value[0] == 0 && value[1] == 0;
          if (no_xy && (options.ignore_z || value[2] == 0)) continue;
          PositionPrior prior;
          prior.image_id = static_cast<image_t>(s.ColumnInt64(0));
          prior.position = Eigen::Vector3d(value[0], value[1], value[2]);
          prior.coordinate_system =
              options.is_gps ? PriorCoordinateSystem::kWgs84 : PriorCoordinateSystem::kCartesian;
          out->priors.push_back(prior);
        }
      });
}

}  // namespace

DatabasePositionPriors ReadPositionPriors(const Database& database, const SpatialPairingOptions& options) {
  DatabasePositionPriors out;
  if (database.HasTable("pose_priors")) {
    out.source = "table pose_priors";
    if (database.HasColumn("pose_priors", "corr_data_id")) {
      ReadPosePriorsOf4x(database, &out);
    } else if (database.HasColumn("pose_priors", "image_id")) {
      ReadPosePriorsByImage(database, &out);
    } else {
      throw DatabaseError("table pose_priors of " + database.path() +
                          " has neither corr_data_id (COLMAP 4.x) nor image_id (COLMAP 3.10 to 3.13)");
    }
    return out;
  }
  out.source = "columns prior_tx, prior_ty, prior_tz of table images";
  if (!database.HasColumn("images", "prior_tx") || !database.HasColumn("images", "prior_ty") ||
      !database.HasColumn("images", "prior_tz")) {
    throw DatabaseError("database " + database.path() +
                        " has no position priors: neither table pose_priors nor the prior_tx, prior_ty, prior_tz "
                        "columns of table images");
  }
  ReadImagePriorColumns(database, options, &out);
  return out;
}

void WritePositionPrior(Database& database, image_t image_id, camera_t camera_id, const PositionPrior& prior) {
  const int64_t system = static_cast<int64_t>(prior.coordinate_system);
  if (database.HasTable("pose_priors") && database.HasColumn("pose_priors", "corr_data_id")) {
    // Unknown covariance and gravity are NaN blobs, as COLMAP writes them.
    const Eigen::Matrix<double, 12, 1> unknown = Eigen::Matrix<double, 12, 1>::Constant(kNaN);
    database.UseStatement("DELETE FROM pose_priors WHERE corr_data_id = ? AND corr_sensor_type = ?",
                          [&](SqliteStatement& s) {
                            s.BindInt64(1, image_id);
                            s.BindInt64(2, kCameraSensorType);
                            s.Execute();
                          });
    database.UseStatement(
        "INSERT INTO pose_priors (corr_data_id, corr_sensor_id, corr_sensor_type, position, position_covariance, "
        "gravity, coordinate_system) VALUES (?, ?, ?, ?, ?, ?, ?)",
        [&](SqliteStatement& s) {
          s.BindInt64(1, image_id);
          s.BindInt64(2, camera_id);
          s.BindInt64(3, kCameraSensorType);
          s.BindBlob(4, prior.position.data(), 3 * sizeof(double));
          s.BindBlob(5, unknown.data(), 9 * sizeof(double));
          s.BindBlob(6, unknown.data(), 3 * sizeof(double));
          s.BindInt64(7, system);
          s.Execute();
        });
    return;
  }
  if (database.HasTable("pose_priors")) {
    database.UseStatement(
        "INSERT OR REPLACE INTO pose_priors (image_id, position, coordinate_system) VALUES (?, ?, ?)",
        [&](SqliteStatement& s) {
          s.BindInt64(1, image_id);
          s.BindBlob(2, prior.position.data(), 3 * sizeof(double));
          s.BindInt64(3, system);
          s.Execute();
        });
    return;
  }
  database.UseStatement("UPDATE images SET prior_tx = ?, prior_ty = ?, prior_tz = ? WHERE image_id = ?",
                        [&](SqliteStatement& s) {
                          for (int k = 0; k < 3; ++k) s.BindDouble(1 + k, prior.position(k));
                          s.BindInt64(4, image_id);
                          s.Execute();
                        });
}

}  // namespace colmap
}  // namespace cashash
