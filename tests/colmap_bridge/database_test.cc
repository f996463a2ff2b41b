// Database bridge tests against databases created by COLMAP itself: a 3.8
// database from `colmap database_creator` and a 4.x one from pycolmap
// (scripts/make_colmap4_database.py). Rows are inserted and inspected with
// raw SQLite so the checks do not trust the code under test.
// Over 600 lines because it is one suite for class Database: one fixture run on
// both COLMAP schemas (DatabaseTest) with the raw-SQLite helpers it needs.
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/LU>

#include "cashash/base/pair_id.h"
#include "colmap_bridge/database.h"

namespace cashash {
namespace colmap {
namespace {

namespace fs = std::filesystem;

bool CommandSucceeds(const std::string& command) { return std::system(command.c_str()) == 0; }

bool HaveColmap() {
  static const bool have = CommandSucceeds("command -v colmap > /dev/null 2>&1");
  return have;
}

bool HavePycolmap() {
  static const bool have = CommandSucceeds("python3 -c 'import pycolmap' > /dev/null 2>&1");
  return have;
}

const std::string kScript = std::string(CASHASH_SOURCE_DIR) + "/scripts/make_colmap4_database.py";

// A fresh directory per test, removed afterwards.
class TempDir {
 public:
  TempDir() {
    static int counter = 0;
    path_ = fs::temp_directory_path() /
            ("cashash_database_test_" + std::to_string(getpid()) + "_" + std::to_string(counter++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ignored;
    fs::remove_all(path_, ignored);
  }
  std::string File(const std::string& name) const { return (path_ / name).string(); }

 private:
  fs::path path_;
};

// A blob column value as read with raw SQLite: null or bytes.
struct RawBlob {
  bool is_null = true;
  std::vector<uint8_t> bytes;

  template <typename T>
  std::vector<T> As() const {
    std::vector<T> values(bytes.size() / sizeof(T));
    if (!values.empty()) std::memcpy(values.data(), bytes.data(), values.size() * sizeof(T));
    return values;
  }
};

// Minimal SQLite access independent of the bridge.
class RawDb {
 public:
  explicit RawDb(const std::string& path) {
    if (sqlite3_open_v2(path.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE,
                        nullptr) != SQLITE_OK) {
      ADD_FAILURE() << "cannot open " << path;
    }
    sqlite3_busy_timeout(db_, 10000);
  }
  ~RawDb() { sqlite3_close_v2(db_); }

  void Exec(const std::string& sql) {
    char* message = nullptr;
    if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &message) != SQLITE_OK) {
      ADD_FAILURE() << sql << ": " << (message ? message : "?");
      sqlite3_free(message);
    }
  }

  // INSERT/REPLACE with one blob parameter (the last '?').
  void ExecWithBlob(const std::string& sql, const void* data, size_t num_bytes) {
    sqlite3_stmt* stmt = nullptr;
    ASSERT_EQ(sqlite3_prepare_v2(db_, sql.c_str(), -1, &stmt, nullptr), SQLITE_OK) << sql;
    sqlite3_bind_blob(stmt, 1, data, static_cast<int>(num_bytes), SQLITE_TRANSIENT);
    EXPECT_EQ(sqlite3_step(stmt), SQLITE_DONE) << sql << ": " << sqlite3_errmsg(db_);
    sqlite3_finalize(stmt);
  }

  int64_t QueryInt(const std::string& sql) {
    sqlite3_stmt* stmt = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db_, sql.c_str(), -1, &stmt, nullptr), SQLITE_OK) << sql;
    int64_t value = -1;
    if (sqlite3_step(stmt) == SQLITE_ROW) value = sqlite3_column_int64(stmt, 0);
    sqlite3_finalize(stmt);
    return value;
  }

  RawBlob QueryBlob(const std::string& sql) {
    sqlite3_stmt* stmt = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db_, sql.c_str(), -1, &stmt, nullptr), SQLITE_OK) << sql;
    RawBlob blob;
    if (sqlite3_step(stmt) == SQLITE_ROW && sqlite3_column_type(stmt, 0) != SQLITE_NULL) {
      blob.is_null = false;
      const auto* data = static_cast<const uint8_t*>(sqlite3_column_blob(stmt, 0));
      blob.bytes.assign(data, data + sqlite3_column_bytes(stmt, 0));
    }
    sqlite3_finalize(stmt);
    return blob;
  }

 private:
  sqlite3* db_ = nullptr;
};

enum class Schema { kColmap38, kColmap4 };

void PrintTo(Schema schema, std::ostream* os) {
  *os << (schema == Schema::kColmap38 ? "COLMAP 3.8 database" : "COLMAP 4.x database");
}

std::string SchemaName(const testing::TestParamInfo<Schema>& info) {
  return info.param == Schema::kColmap38 ? "Colmap38" : "Colmap4";
}

// Creates an empty database as COLMAP does; false when the tool is missing.
bool RunColmapDatabaseCreator(Schema schema, const std::string& path) {
  if (schema == Schema::kColmap38) {
    if (!HaveColmap()) return false;
    EXPECT_TRUE(CommandSucceeds("QT_QPA_PLATFORM=offscreen colmap database_creator "
                                "--database_path '" + path + "' > /dev/null 2>&1"));
  } else {
    if (!HavePycolmap()) return false;
    EXPECT_TRUE(CommandSucceeds("python3 '" + kScript + "' '" + path + "'"));
  }
  return fs::exists(path);
}

// Starting COLMAP or Python costs about a second: each kind of database is
// created once per run and copied for every test. Both tools close their
// databases cleanly, so the main file holds everything.
bool CreateColmapDatabase(Schema schema, const std::string& path) {
  static TempDir templates;
  static std::string created[2];
  std::string& template_path = created[static_cast<int>(schema)];
  if (template_path.empty()) {
    const std::string candidate = templates.File(schema == Schema::kColmap38 ? "38.db" : "4.db");
    if (!RunColmapDatabaseCreator(schema, candidate)) return false;
    EXPECT_FALSE(fs::exists(candidate + "-wal")) << "template left a WAL file";
    template_path = candidate;
  }
  fs::copy_file(template_path, path);
  return true;
}

std::string SkipMessage(Schema schema) {
  return schema == Schema::kColmap38 ? "colmap is not on PATH" : "pycolmap cannot be imported";
}

std::vector<float> KeypointRows(int rows, int cols) {
  std::vector<float> values(rows * cols);
  for (int i = 0; i < rows * cols; ++i) values[i] = 0.5f + static_cast<float>(i);
  return values;
}

std::vector<uint8_t> DescriptorRows(int rows, uint8_t seed) {
  std::vector<uint8_t> values(rows * kDescriptorDim);
  for (size_t i = 0; i < values.size(); ++i) values[i] = static_cast<uint8_t>(seed + i * 7);
  return values;
}

// Expectations about a pose: cam2_from_cam1 inverted.
void InvertPose(const Eigen::Vector4d& qvec, const Eigen::Vector3d& tvec, Eigen::Vector4d* qinv,
                Eigen::Vector3d* tinv) {
  const Eigen::Quaterniond q(qvec(0), qvec(1), qvec(2), qvec(3));
  const Eigen::Quaterniond inverse = q.conjugate();
  *qinv = Eigen::Vector4d(inverse.w(), inverse.x(), inverse.y(), inverse.z());
  *tinv = -(inverse * tvec);
}

Eigen::Matrix3d RowMajor(const std::vector<double>& values) {
  Eigen::Matrix3d m;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m(r, c) = values.at(3 * r + c);
  }
  return m;
}

// Equal up to a non-zero scale (homographies).
void ExpectProportional(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  const Eigen::Matrix3d na = a / a.norm();
  const Eigen::Matrix3d nb = b / b.norm();
  const double sign = (na.cwiseProduct(nb).sum() < 0) ? -1.0 : 1.0;
  EXPECT_LT((na - sign * nb).norm(), 1e-9) << a << "\nvs\n" << b;
}

void ExpectSameRotation(const Eigen::Vector4d& a, const Eigen::Vector4d& b) {
  EXPECT_NEAR(std::abs(a.normalized().dot(b.normalized())), 1.0, 1e-9) << a.transpose() << " vs "
                                                                         << b.transpose();
}

FeatureMatches Swapped(const FeatureMatches& matches) {
  FeatureMatches swapped;
  for (const FeatureMatch& m : matches) swapped.push_back({m.point2D_idx2, m.point2D_idx1});
  return swapped;
}

// Geometries used by several tests.
TwoViewGeometry UncalibratedGeometry() {
  TwoViewGeometry g;
  g.config = kUncalibrated;
  g.F << 1e-7, -2e-6, 3e-4, 4e-6, 5e-8, -6e-3, -7e-4, 8e-3, 1.0;
  g.H << 1.1, 0.02, 5.0, -0.03, 0.95, -7.0, 1e-5, 2e-5, 1.0;
  g.inlier_matches = {{0, 1}, {2, 0}, {4, 2}};
  return g;
}

TwoViewGeometry CalibratedGeometry() {
  TwoViewGeometry g;
  g.config = kCalibrated;
  g.F << 2e-7, -1e-6, 4e-4, 3e-6, 6e-8, -5e-3, -8e-4, 7e-3, 1.0;
  g.E << 0.0, -0.3, 0.2, 0.3, 0.0, -0.9, -0.2, 0.9, 0.0;
  g.H << 0.9, -0.01, 3.0, 0.04, 1.05, 2.0, -2e-5, 1e-5, 1.0;
  const Eigen::Quaterniond q = Eigen::Quaterniond(0.9, 0.1, -0.2, 0.3).normalized();
  g.qvec = Eigen::Vector4d(q.w(), q.x(), q.y(), q.z());
  g.tvec = Eigen::Vector3d(0.6, -0.0, 0.8);
  g.inlier_matches = {{0, 4}, {3, 2}};
  return g;
}

class DatabaseTest : public testing::TestWithParam<Schema> {
 protected:
  void SetUp() override {
    path_ = dir_.File("database.db");
    if (!CreateColmapDatabase(GetParam(), path_)) GTEST_SKIP() << SkipMessage(GetParam());
    RawDb raw(path_);
    const double params1[] = {500, 500, 320, 240};
    raw.ExecWithBlob("INSERT INTO cameras(camera_id, model, width, height, params, "
                     "prior_focal_length) VALUES (1, 1, 640, 480, ?, 1)",
                     params1, sizeof(params1));
    const double params2[] = {600, 400, 300, 0.01};
    raw.ExecWithBlob("INSERT INTO cameras(camera_id, model, width, height, params, "
                     "prior_focal_length) VALUES (2, 2, 800, 600, ?, 0)",
                     params2, sizeof(params2));
    // Inserted out of order: ReadAllImages must sort by id.
    raw.Exec("INSERT INTO images(image_id, name, camera_id) VALUES (3, 'c.jpg', 2)");
    raw.Exec("INSERT INTO images(image_id, name, camera_id) VALUES (1, 'a.jpg', 1)");
    raw.Exec("INSERT INTO images(image_id, name, camera_id) VALUES (2, 'b.jpg', 1)");
    raw.Exec("INSERT INTO images(image_id, name, camera_id) VALUES (4, 'd.jpg', 2)");
    // Image 4 has neither keypoints nor descriptors.
    InsertKeypoints(raw, 1, 5, 6);
    InsertKeypoints(raw, 2, 3, 4);
    InsertKeypoints(raw, 3, 4, 2);
    InsertDescriptors(raw, 1, 5, 128, DescriptorRows(5, 1));
    InsertDescriptors(raw, 2, 3, 128, DescriptorRows(3, 2));
    InsertDescriptors(raw, 3, 4, 128, DescriptorRows(4, 3));
  }

  bool Is4x() const { return GetParam() == Schema::kColmap4; }

  static void InsertKeypoints(RawDb& raw, int image_id, int rows, int cols) {
    const std::vector<float> values = KeypointRows(rows, cols);
    raw.ExecWithBlob("INSERT OR REPLACE INTO keypoints(image_id, rows, cols, data) VALUES (" +
                         std::to_string(image_id) + ", " + std::to_string(rows) + ", " +
                         std::to_string(cols) + ", ?)",
                     values.data(), values.size() * sizeof(float));
  }

  void InsertDescriptors(RawDb& raw, int image_id, int rows, int cols,
                         const std::vector<uint8_t>& bytes, int type = 0) {
    const std::string columns = Is4x() ? "image_id, type, rows, cols, data"
                                       : "image_id, rows, cols, data";
    const std::string type_value = Is4x() ? std::to_string(type) + ", " : "";
    raw.ExecWithBlob("INSERT OR REPLACE INTO descriptors(" + columns + ") VALUES (" +
                         std::to_string(image_id) + ", " + type_value + std::to_string(rows) +
                         ", " + std::to_string(cols) + ", ?)",
                     bytes.data(), bytes.size());
  }

  // The DatabaseError message of `fn`, or "" if it did not throw.
  template <typename Fn>
  static std::string ErrorOf(Fn fn) {
    try {
      fn();
    } catch (const DatabaseError& error) {
      return error.what();
    }
    return "";
  }

  TempDir dir_;
  std::string path_;
};

TEST_P(DatabaseTest, DetectsSchema) {
  Database db(path_);
  const SchemaInfo& schema = db.schema();
  if (Is4x()) {
    EXPECT_GE(schema.user_version, 4000000);
    EXPECT_TRUE(schema.descriptors_have_type);
    EXPECT_TRUE(schema.has_frames);
    // pycolmap 4.2.1 already has camera1 / camera2 in two_view_geometries.
    EXPECT_TRUE(schema.two_view_has_camera_columns);
    EXPECT_NE(schema.Describe().find("4.x-style"), std::string::npos) << schema.Describe();
  } else {
    EXPECT_EQ(schema.user_version, 3800);
    EXPECT_FALSE(schema.descriptors_have_type);
    EXPECT_FALSE(schema.has_frames);
    EXPECT_FALSE(schema.two_view_has_camera_columns);
    EXPECT_NE(schema.Describe().find("3.8-style"), std::string::npos) << schema.Describe();
  }
  EXPECT_EQ(db.path(), path_);
}

TEST_P(DatabaseTest, OpeningDoesNotChangeJournalModeOrSchema) {
  RawDb before(path_);
  const RawBlob schema_before = before.QueryBlob("SELECT group_concat(sql) FROM sqlite_master");
  const std::string mode_query = "PRAGMA journal_mode";
  { Database db(path_); }
  RawDb after(path_);
  EXPECT_EQ(after.QueryBlob("SELECT group_concat(sql) FROM sqlite_master").bytes,
            schema_before.bytes);
  // Both COLMAP versions create WAL databases; WAL is a property of the file.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open_v2(path_.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  sqlite3_stmt* stmt = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, mode_query.c_str(), -1, &stmt, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_step(stmt), SQLITE_ROW);
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(stmt, 0)), "wal");
  sqlite3_finalize(stmt);
  sqlite3_close_v2(db);
}

TEST_P(DatabaseTest, ReadsCamerasAndImages) {
  Database db(path_, /*read_only=*/true);
  const std::vector<Camera> cameras = db.ReadAllCameras();
  ASSERT_EQ(cameras.size(), 2u);
  EXPECT_EQ(cameras[0].camera_id, 1u);
  EXPECT_EQ(cameras[0].model_id, 1);
  EXPECT_EQ(cameras[0].width, 640u);
  EXPECT_EQ(cameras[0].height, 480u);
  EXPECT_EQ(cameras[0].params, (std::vector<double>{500, 500, 320, 240}));
  EXPECT_TRUE(cameras[0].has_prior_focal_length);
  EXPECT_EQ(cameras[1].model_id, 2);
  EXPECT_EQ(cameras[1].params, (std::vector<double>{600, 400, 300, 0.01}));
  EXPECT_FALSE(cameras[1].has_prior_focal_length);

  const std::vector<Image> images = db.ReadAllImages();
  ASSERT_EQ(images.size(), 4u);
  const char* names[] = {"a.jpg", "b.jpg", "c.jpg", "d.jpg"};
  const camera_t camera_ids[] = {1, 1, 2, 2};
  for (size_t i = 0; i < images.size(); ++i) {
    EXPECT_EQ(images[i].image_id, i + 1);
    EXPECT_EQ(images[i].name, names[i]);
    EXPECT_EQ(images[i].camera_id, camera_ids[i]);
  }
}

TEST_P(DatabaseTest, ReadsKeypointsOfEveryWidth) {
  Database db(path_, /*read_only=*/true);
  // 6 columns: copied.
  const Keypoints k6 = db.ReadKeypoints(1);
  ASSERT_EQ(k6.size(), 5u);
  const std::vector<float> v6 = KeypointRows(5, 6);
  for (size_t i = 0; i < k6.size(); ++i) {
    EXPECT_EQ(k6[i].x, v6[6 * i]);
    EXPECT_EQ(k6[i].y, v6[6 * i + 1]);
    EXPECT_EQ(k6[i].a11, v6[6 * i + 2]);
    EXPECT_EQ(k6[i].a12, v6[6 * i + 3]);
    EXPECT_EQ(k6[i].a21, v6[6 * i + 4]);
    EXPECT_EQ(k6[i].a22, v6[6 * i + 5]);
  }
  // 4 columns: x, y, scale, orientation -> rotation scaled by `scale`.
  const Keypoints k4 = db.ReadKeypoints(2);
  ASSERT_EQ(k4.size(), 3u);
  const std::vector<float> v4 = KeypointRows(3, 4);
  for (size_t i = 0; i < k4.size(); ++i) {
    const float scale = v4[4 * i + 2];
    const float orientation = v4[4 * i + 3];
    EXPECT_EQ(k4[i].x, v4[4 * i]);
    EXPECT_EQ(k4[i].y, v4[4 * i + 1]);
    EXPECT_FLOAT_EQ(k4[i].a11, scale * std::cos(orientation));
    EXPECT_FLOAT_EQ(k4[i].a12, -scale * std::sin(orientation));
    EXPECT_FLOAT_EQ(k4[i].a21, scale * std::sin(orientation));
    EXPECT_FLOAT_EQ(k4[i].a22, scale * std::cos(orientation));
    EXPECT_NEAR(k4[i].ComputeScale(), scale, 1e-4f * scale);
  }
  // 2 columns: identity shape.
  const Keypoints k2 = db.ReadKeypoints(3);
  ASSERT_EQ(k2.size(), 4u);
  EXPECT_EQ(k2[3].x, 6.5f);
  EXPECT_EQ(k2[3].y, 7.5f);
  EXPECT_EQ(k2[3].a11, 1.f);
  EXPECT_EQ(k2[3].a12, 0.f);
  EXPECT_EQ(k2[3].a21, 0.f);
  EXPECT_EQ(k2[3].a22, 1.f);
  // No row: no features, not an error.
  EXPECT_TRUE(db.ReadKeypoints(4).empty());
  EXPECT_EQ(db.NumKeypoints(1), 5u);
  EXPECT_EQ(db.NumKeypoints(3), 4u);
  EXPECT_EQ(db.NumKeypoints(4), 0u);
}

TEST_P(DatabaseTest, ReadsDescriptors) {
  Database db(path_, /*read_only=*/true);
  const FeatureDescriptors d = db.ReadDescriptors(2);
  EXPECT_EQ(d.rows(), 3u);
  EXPECT_EQ(d.data, DescriptorRows(3, 2));
  EXPECT_TRUE(db.ReadDescriptors(4).data.empty());
  EXPECT_EQ(db.NumDescriptors(1), 5u);
  EXPECT_EQ(db.NumDescriptors(4), 0u);
}

TEST_P(DatabaseTest, RejectsMalformedFeatures) {
  {
    RawDb raw(path_);
    InsertDescriptors(raw, 1, 5, 64, std::vector<uint8_t>(5 * 64));
    InsertDescriptors(raw, 2, 10, 128, std::vector<uint8_t>(1000));
    InsertDescriptors(raw, 3, 4, 128, std::vector<uint8_t>(4 * 128 * sizeof(float)));
    InsertKeypoints(raw, 1, 5, 3);
    const std::vector<float> short_blob(7);
    raw.ExecWithBlob("UPDATE keypoints SET data = ? WHERE image_id = 2", short_blob.data(),
                     short_blob.size() * sizeof(float));
  }
  Database db(path_, /*read_only=*/true);
  EXPECT_EQ(ErrorOf([&] { db.ReadDescriptors(1); }),
            "descriptors of image 1 (a.jpg): expected uint8 x 128 SIFT descriptors, found 64 "
            "columns");
  const std::string size_error = ErrorOf([&] { db.ReadDescriptors(2); });
  EXPECT_NE(size_error.find("descriptors of image 2 (b.jpg): blob size 1000 does not match rows "
                            "x cols = 10 x 128"),
            std::string::npos)
      << size_error;
  const std::string float_error = ErrorOf([&] { db.ReadDescriptors(3); });
  EXPECT_NE(float_error.find("descriptors of image 3 (c.jpg)"), std::string::npos) << float_error;
  EXPECT_NE(float_error.find("float32"), std::string::npos) << float_error;
  EXPECT_EQ(ErrorOf([&] { db.ReadKeypoints(1); }),
            "keypoints of image 1 (a.jpg): expected float32 keypoints with 2, 4 or 6 columns, "
            "found 3 columns");
  const std::string keypoint_size_error = ErrorOf([&] { db.ReadKeypoints(2); });
  EXPECT_NE(keypoint_size_error.find("keypoints of image 2 (b.jpg): blob size 28 does not match "
                                     "rows x cols = 3 x 4"),
            std::string::npos)
      << keypoint_size_error;
}

TEST_P(DatabaseTest, RejectsAlikedDescriptors) {
  if (!Is4x()) GTEST_SKIP() << "3.8 databases have no descriptor type";
  {
    RawDb raw(path_);
    InsertDescriptors(raw, 2, 3, 512, std::vector<uint8_t>(3 * 512), /*type=*/1);
  }
  Database db(path_, /*read_only=*/true);
  EXPECT_EQ(ErrorOf([&] { db.ReadDescriptors(2); }),
            "descriptors of image 2 (b.jpg): descriptor type ALIKED_N16ROT (1) is not "
            "supported; extract SIFT features");
  EXPECT_EQ(db.ReadDescriptors(1).rows(), 5u);
}

// One test because every assertion reads back the rows written at its
// start: through our reader in both pair orders, then as raw SQLite rows.
TEST_P(DatabaseTest, WritesMatchesAndGeometriesAsColmap) {
  const FeatureMatches matches12 = {{0, 1}, {1, 1}, {2, 0}, {4, 2}};
  const FeatureMatches matches31 = {{0, 4}, {3, 2}, {1, 1}};
  const TwoViewGeometry g12 = UncalibratedGeometry();
  const TwoViewGeometry g31 = CalibratedGeometry();
  TwoViewGeometry degenerate;
  degenerate.config = kDegenerate;
  {
    Database db(path_);
    db.BeginTransaction();
    db.WriteMatches(1, 2, matches12);
    db.WriteTwoViewGeometry(1, 2, g12);
    db.WriteMatches(3, 1, matches31);
    db.WriteTwoViewGeometry(3, 1, g31);
    db.WriteMatches(3, 2, {});
    db.WriteTwoViewGeometry(3, 2, degenerate);
    db.Commit();

    // Our reader, in both orders.
    EXPECT_EQ(db.ReadMatches(1, 2), matches12);
    EXPECT_EQ(db.ReadMatches(2, 1), Swapped(matches12));
    EXPECT_EQ(db.ReadMatches(3, 1), matches31);
    EXPECT_TRUE(db.ReadMatches(2, 3).empty());
    EXPECT_TRUE(db.ReadMatches(1, 4).empty());  // no row at all

    const TwoViewGeometry r12 = db.ReadTwoViewGeometry(1, 2);
    EXPECT_EQ(r12.config, kUncalibrated);
    EXPECT_EQ(r12.inlier_matches, g12.inlier_matches);
    EXPECT_EQ(r12.F, g12.F);
    EXPECT_EQ(r12.H, g12.H);
    EXPECT_TRUE(r12.E.isZero());

    const TwoViewGeometry r31 = db.ReadTwoViewGeometry(3, 1);
    EXPECT_EQ(r31.config, kCalibrated);
    EXPECT_EQ(r31.inlier_matches, g31.inlier_matches);
    EXPECT_TRUE(r31.F.isApprox(g31.F, 1e-12));
    EXPECT_TRUE(r31.E.isApprox(g31.E, 1e-12));
    ExpectProportional(r31.H, g31.H);
    ExpectSameRotation(r31.qvec, g31.qvec);
    EXPECT_TRUE(r31.tvec.isApprox(g31.tvec, 1e-9)) << r31.tvec.transpose();

    const TwoViewGeometry r23 = db.ReadTwoViewGeometry(2, 3);
    EXPECT_EQ(r23.config, kDegenerate);
    EXPECT_TRUE(r23.inlier_matches.empty());
    EXPECT_EQ(db.ReadTwoViewGeometry(1, 4).config, kUndefined);

    const std::unordered_set<pair_t> completed = db.ReadCompletedPairIds();
    EXPECT_EQ(completed, (std::unordered_set<pair_t>{2147483647ull * 1 + 2,
                                                    2147483647ull * 1 + 3,
                                                    2147483647ull * 2 + 3}));
  }

  // The raw rows.
  RawDb raw(path_);
  const pair_t p12 = 2147483647ull * 1 + 2;
  const pair_t p13 = 2147483647ull * 1 + 3;
  const pair_t p23 = 2147483647ull * 2 + 3;
  EXPECT_EQ(ImagePairToPairId(3, 1), p13);
  auto where = [](pair_t pair_id) { return " WHERE pair_id = " + std::to_string(pair_id); };
  EXPECT_EQ(raw.QueryInt("SELECT count(*) FROM matches"), 3);
  EXPECT_EQ(raw.QueryInt("SELECT count(*) FROM two_view_geometries"), 3);

  EXPECT_EQ(raw.QueryInt("SELECT rows FROM matches" + where(p12)), 4);
  EXPECT_EQ(raw.QueryInt("SELECT cols FROM matches" + where(p12)), 2);
  EXPECT_EQ(raw.QueryBlob("SELECT data FROM matches" + where(p12)).As<uint32_t>(),
            (std::vector<uint32_t>{0, 1, 1, 1, 2, 0, 4, 2}));
  // Written as (3, 1): column 0 now indexes image 1.
  EXPECT_EQ(raw.QueryBlob("SELECT data FROM matches" + where(p13)).As<uint32_t>(),
            (std::vector<uint32_t>{4, 0, 2, 3, 1, 1}));
  EXPECT_EQ(raw.QueryBlob("SELECT data FROM two_view_geometries" + where(p13)).As<uint32_t>(),
            (std::vector<uint32_t>{4, 0, 2, 3}));
  EXPECT_EQ(raw.QueryInt("SELECT config FROM two_view_geometries" + where(p13)), kCalibrated);

  // Empty sets: rows 0, cols 2, data NULL, as both COLMAP versions write them.
  for (const std::string table : {"matches", "two_view_geometries"}) {
    EXPECT_EQ(raw.QueryInt("SELECT rows FROM " + table + where(p23)), 0);
    EXPECT_EQ(raw.QueryInt("SELECT cols FROM " + table + where(p23)), 2);
    EXPECT_TRUE(raw.QueryBlob("SELECT data FROM " + table + where(p23)).is_null) << table;
  }
  EXPECT_EQ(raw.QueryInt("SELECT config FROM two_view_geometries" + where(p23)), kDegenerate);
  for (const char* column : {"F", "E", "H", "qvec", "tvec"}) {
    EXPECT_TRUE(raw.QueryBlob(std::string("SELECT ") + column + " FROM two_view_geometries" +
                              where(p23))
                    .is_null)
        << column;
  }

  // Swapped geometry: F and E transposed, H inverted, pose inverted; all
  // row-major.
  auto matrix = [&](const char* column, pair_t pair_id) {
    return RowMajor(
        raw.QueryBlob(std::string("SELECT ") + column + " FROM two_view_geometries" + where(pair_id))
            .As<double>());
  };
  EXPECT_TRUE(matrix("F", p13).isApprox(g31.F.transpose(), 1e-12));
  EXPECT_TRUE(matrix("E", p13).isApprox(g31.E.transpose(), 1e-12));
  ExpectProportional(matrix("H", p13), g31.H.inverse());
  Eigen::Vector4d qinv;
  Eigen::Vector3d tinv;
  InvertPose(g31.qvec, g31.tvec, &qinv, &tinv);
  const std::vector<double> qvec =
      raw.QueryBlob("SELECT qvec FROM two_view_geometries" + where(p13)).As<double>();
  const std::vector<double> tvec =
      raw.QueryBlob("SELECT tvec FROM two_view_geometries" + where(p13)).As<double>();
  ASSERT_EQ(qvec.size(), 4u);
  ASSERT_EQ(tvec.size(), 3u);
  ExpectSameRotation(Eigen::Vector4d(qvec[0], qvec[1], qvec[2], qvec[3]), qinv);
  EXPECT_TRUE(Eigen::Vector3d(tvec[0], tvec[1], tvec[2]).isApprox(tinv, 1e-9));

  // Unswapped pair, unset E and pose: 3.8 writes zeros / identity, 4.x NULL.
  EXPECT_EQ(matrix("F", p12), g12.F);
  EXPECT_EQ(matrix("H", p12), g12.H);
  const RawBlob E12 = raw.QueryBlob("SELECT E FROM two_view_geometries" + where(p12));
  const RawBlob q12 = raw.QueryBlob("SELECT qvec FROM two_view_geometries" + where(p12));
  const RawBlob t12 = raw.QueryBlob("SELECT tvec FROM two_view_geometries" + where(p12));
  if (Is4x()) {
    EXPECT_TRUE(E12.is_null);
    EXPECT_TRUE(q12.is_null);
    EXPECT_TRUE(t12.is_null);
    EXPECT_TRUE(raw.QueryBlob("SELECT camera1 FROM two_view_geometries" + where(p12)).is_null);
    EXPECT_TRUE(raw.QueryBlob("SELECT camera2 FROM two_view_geometries" + where(p12)).is_null);
  } else {
    EXPECT_EQ(E12.As<double>(), std::vector<double>(9, 0.0));
    EXPECT_EQ(q12.As<double>(), (std::vector<double>{1, 0, 0, 0}));
    EXPECT_EQ(t12.As<double>(), std::vector<double>(3, 0.0));
  }
}

// pycolmap 4.2.1 reads a database we wrote, with the same values.
TEST_P(DatabaseTest, PycolmapReadsWhatWeWrite) {
  if (!Is4x()) GTEST_SKIP() << "pycolmap reads 4.x databases";
  const FeatureMatches matches31 = {{0, 4}, {3, 2}, {1, 1}};
  const TwoViewGeometry g12 = UncalibratedGeometry();
  const TwoViewGeometry g31 = CalibratedGeometry();
  {
    Database db(path_);
    db.WriteMatches(1, 2, {{0, 1}, {2, 0}});
    db.WriteTwoViewGeometry(1, 2, g12);
    db.WriteMatches(3, 1, matches31);
    db.WriteTwoViewGeometry(3, 1, g31);
  }
  const std::string pairs_file = dir_.File("pairs.txt");
  std::ofstream(pairs_file) << "1 2\n3 1\n";
  const std::string command =
      "python3 '" + kScript + "' --dump '" + path_ + "' < '" + pairs_file + "'";
  FILE* pipe = popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string output;
  char buffer[4096];
  while (size_t n = fread(buffer, 1, sizeof(buffer), pipe)) output.append(buffer, n);
  ASSERT_EQ(pclose(pipe), 0) << output;

  std::istringstream lines(output);
  auto expect_line = [&](const std::string& expected) {
    std::string line;
    ASSERT_TRUE(std::getline(lines, line));
    EXPECT_EQ(line, expected);
  };
  auto read_values = [&](const std::string& key, int count) {
    std::string line;
    std::vector<double> values;
    EXPECT_TRUE(std::getline(lines, line));
    std::istringstream in(line);
    std::string name;
    in >> name;
    EXPECT_EQ(name, key);
    double v;
    while (in >> v) values.push_back(v);
    EXPECT_EQ(static_cast<int>(values.size()), count) << line;
    values.resize(count);
    return values;
  };

  expect_line("pair 1 2");
  expect_line("matches 2 0 1 2 0");
  expect_line("config 3");
  expect_line("inliers 3 0 1 2 0 4 2");
  EXPECT_EQ(RowMajor(read_values("F", 9)), g12.F);
  expect_line("E none");
  EXPECT_EQ(RowMajor(read_values("H", 9)), g12.H);
  expect_line("pose none");

  // Read in the order we wrote it: pycolmap undoes our inversion.
  expect_line("pair 3 1");
  expect_line("matches 3 0 4 3 2 1 1");
  expect_line("config 2");
  expect_line("inliers 2 0 4 3 2");
  EXPECT_TRUE(RowMajor(read_values("F", 9)).isApprox(g31.F, 1e-12));
  EXPECT_TRUE(RowMajor(read_values("E", 9)).isApprox(g31.E, 1e-12));
  ExpectProportional(RowMajor(read_values("H", 9)), g31.H);
  const std::vector<double> pose = read_values("pose", 7);
  ExpectSameRotation(Eigen::Vector4d(pose[0], pose[1], pose[2], pose[3]), g31.qvec);
  EXPECT_TRUE(Eigen::Vector3d(pose[4], pose[5], pose[6]).isApprox(g31.tvec, 1e-9));
}

TEST_P(DatabaseTest, CompletedPairsNeedBothRows) {
  Database db(path_);
  db.WriteMatches(1, 2, {{0, 0}});
  db.WriteTwoViewGeometry(2, 1, TwoViewGeometry());
  db.WriteMatches(1, 3, {{0, 0}});               // no geometry: to be redone
  db.WriteTwoViewGeometry(2, 3, TwoViewGeometry());  // no matches: to be redone
  EXPECT_EQ(db.ReadCompletedPairIds(), (std::unordered_set<pair_t>{ImagePairToPairId(1, 2)}));

  db.ClearMatchesAndGeometries();
  EXPECT_TRUE(db.ReadCompletedPairIds().empty());
  RawDb raw(path_);
  EXPECT_EQ(raw.QueryInt("SELECT count(*) FROM matches"), 0);
  EXPECT_EQ(raw.QueryInt("SELECT count(*) FROM two_view_geometries"), 0);
}

TEST_P(DatabaseTest, RollbackWritesNothing) {
  Database db(path_);
  db.BeginTransaction();
  EXPECT_NE(ErrorOf([&] { db.BeginTransaction(); }), "");
  db.WriteMatches(1, 2, {{0, 0}, {1, 1}});
  db.WriteTwoViewGeometry(1, 2, UncalibratedGeometry());
  EXPECT_EQ(db.ReadMatches(1, 2).size(), 2u);  // visible inside the transaction
  db.Rollback();
  EXPECT_TRUE(db.ReadMatches(1, 2).empty());
  EXPECT_TRUE(db.ReadCompletedPairIds().empty());
  RawDb raw(path_);
  EXPECT_EQ(raw.QueryInt("SELECT count(*) FROM matches"), 0);
  EXPECT_EQ(raw.QueryInt("SELECT count(*) FROM two_view_geometries"), 0);
  EXPECT_NE(ErrorOf([&] { db.Commit(); }), "");
  EXPECT_NE(ErrorOf([&] { db.Rollback(); }), "");
}

TEST_P(DatabaseTest, ClosingWithAnOpenTransactionRollsBack) {
  {
    Database db(path_);
    db.BeginTransaction();
    db.WriteMatches(1, 2, {{0, 0}});
  }
  RawDb raw(path_);
  EXPECT_EQ(raw.QueryInt("SELECT count(*) FROM matches"), 0);
}

TEST_P(DatabaseTest, ReadOnlyRefusesWrites) {
  Database db(path_, /*read_only=*/true);
  EXPECT_EQ(ErrorOf([&] { db.WriteMatches(1, 2, {}); }), "database opened read-only: " + path_);
  EXPECT_NE(ErrorOf([&] { db.ClearMatchesAndGeometries(); }), "");
}

// A writer holding the lock makes us wait (busy timeout) instead of failing.
TEST_P(DatabaseTest, WaitsForAConcurrentWriter) {
  Database db(path_);
  RawDb other(path_);
  other.Exec("BEGIN IMMEDIATE");
  other.Exec("INSERT INTO matches(pair_id, rows, cols, data) VALUES (7, 0, 2, NULL)");
  std::thread releaser([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    other.Exec("COMMIT");
  });
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(ErrorOf([&] { db.WriteMatches(1, 2, {{0, 0}}); }), "");
  const double waited =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  releaser.join();
  EXPECT_GT(waited, 0.2);
  EXPECT_EQ(db.ReadMatches(1, 2).size(), 1u);
}

// 100k pairs (an exhaustive run over ~450 images) in one transaction, every
// other one given swapped: all of them read back as completed pairs. Rows
// per second: scripts/bench/write_rows_bench.
TEST_P(DatabaseTest, WritesManyPairsInOneTransaction) {
  constexpr image_t kNumImages = 448;  // 448 * 447 / 2 = 100128 pairs
  FeatureMatches matches(25);
  for (size_t i = 0; i < matches.size(); ++i) {
    matches[i] = {static_cast<point2D_t>(i), static_cast<point2D_t>(2 * i)};
  }
  TwoViewGeometry geometry = UncalibratedGeometry();
  geometry.inlier_matches.assign(matches.begin(), matches.begin() + 20);

  Database db(path_);
  db.BeginTransaction();
  size_t num_pairs = 0;
  for (image_t i = 1; i <= kNumImages; ++i) {
    for (image_t j = i + 1; j <= kNumImages; ++j) {
      // Every other pair written swapped, as a pair scheduler may.
      const bool swap = (i + j) % 2 == 0;
      db.WriteMatches(swap ? j : i, swap ? i : j, matches);
      db.WriteTwoViewGeometry(swap ? j : i, swap ? i : j, geometry);
      ++num_pairs;
    }
  }
  db.Commit();
  EXPECT_EQ(db.ReadCompletedPairIds().size(), num_pairs);
  EXPECT_EQ(db.ReadMatches(2, 1).size(), matches.size());
  EXPECT_EQ(db.ReadTwoViewGeometry(kNumImages - 1, kNumImages).inlier_matches.size(), 20u);
}

INSTANTIATE_TEST_SUITE_P(Schemas, DatabaseTest,
                         testing::Values(Schema::kColmap38, Schema::kColmap4), SchemaName);

// Errors before any schema exists.
TEST(DatabaseOpenTest, MissingFile) {
  TempDir dir;
  const std::string path = dir.File("missing.db");
  try {
    Database db(path);
    FAIL() << "opened a missing file";
  } catch (const DatabaseError& error) {
    EXPECT_EQ(std::string(error.what()), "database file not found: " + path);
  }
  EXPECT_FALSE(fs::exists(path)) << "opening must not create the file";
}

TEST(DatabaseOpenTest, NotSqlite) {
  TempDir dir;
  const std::string path = dir.File("notes.db");
  std::ofstream(path) << std::string(2000, 'x') << "\nthis is not a database\n";
  try {
    Database db(path, /*read_only=*/true);
    FAIL() << "opened a text file";
  } catch (const DatabaseError& error) {
    EXPECT_EQ(std::string(error.what()), "not a SQLite database: " + path);
  }
}

TEST(DatabaseOpenTest, MissingTables) {
  TempDir dir;
  const std::string path = dir.File("partial.db");
  {
    RawDb raw(path);
    raw.Exec("CREATE TABLE cameras(camera_id INTEGER PRIMARY KEY, model INTEGER, width INTEGER, "
             "height INTEGER, params BLOB, prior_focal_length INTEGER)");
    raw.Exec("CREATE TABLE images(image_id INTEGER PRIMARY KEY, name TEXT, camera_id INTEGER)");
    raw.Exec("CREATE TABLE keypoints(image_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, "
             "data BLOB)");
  }
  auto error_of_open = [&](bool read_only) -> std::string {
    try {
      Database db(path, read_only);
    } catch (const DatabaseError& error) {
      return error.what();
    }
    return "";
  };
  EXPECT_NE(error_of_open(true).find("has no table 'descriptors'"), std::string::npos)
      << error_of_open(true);
  {
    RawDb raw(path);
    raw.Exec("CREATE TABLE descriptors(image_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, "
             "data BLOB)");
  }
  // Reading features needs no match tables; writing does.
  EXPECT_EQ(error_of_open(true), "");
  EXPECT_NE(error_of_open(false).find("has no table 'matches'"), std::string::npos)
      << error_of_open(false);
}

}  // namespace
}  // namespace colmap
}  // namespace cashash
