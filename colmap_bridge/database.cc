// COLMAP database access. What COLMAP itself stores was checked against
// databases written by COLMAP 3.8 (exhaustive_matcher) and pycolmap 4.2.1
// (Database.write_*), see tests/colmap_bridge/database_test.cc:
// - F, E, H are 9 float64 row-major; qvec is [w, x, y, z].
// - Empty match sets: rows = 0, cols = 2, data NULL (both versions).
// - 3.8, pair with inliers: F, E, H, qvec, tvec are all written, unset
//   matrices as 72 zero bytes. 3.8, pair without inliers (config 0): F, E, H,
//   qvec, tvec are NULL.
// - 4.x: every unset optional is NULL: a matrix the estimator did not set,
//   the pose when it was not computed, and camera1 / camera2. The latter (a
//   serialized Camera, not an id) hold cameras *estimated* by focal-solving
//   configurations; geometries verified with the database intrinsics leave
//   them NULL, and so do we.
//
// Over 600 lines because it is the whole of class Database: every table's reads
// and writes share the private Impl (one connection, cached statements, schema).
#include "colmap_bridge/database.h"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <sqlite3.h>
#include <unistd.h>

#include "cashash/base/pair_id.h"
#include "colmap_bridge/blob_codec.h"
#include "colmap_bridge/pair_id_runs.h"
#include "colmap_bridge/sqlite_statement.h"

namespace cashash {
namespace colmap {
namespace {

// COLMAP 4.x numbers user_version as major * 1000000 + minor * 10000 + ...
// (4.2.1 -> 4020100); 3.x used major * 1000 + minor * 100 (3.8 -> 3800).
constexpr int kFirstUserVersion4x = 4000000;

bool IsZero(const Eigen::Matrix3d& m) { return (m.array() == 0.0).all(); }

bool PoseIsUnset(const TwoViewGeometry& g) {
  return g.qvec == Eigen::Vector4d(1, 0, 0, 0) && (g.tvec.array() == 0.0).all();
}

MatrixBlob MatrixBlobAt(const SqliteStatement& s, int first_col) {
  MatrixBlob blob;
  blob.rows = s.ColumnInt64(first_col);
  blob.cols = s.ColumnInt64(first_col + 1);
  blob.data = s.ColumnBlob(first_col + 2);
  blob.num_bytes = s.ColumnBytes(first_col + 2);
  return blob;
}

}  // namespace

bool ParseDiskSync(const std::string& text, DiskSync* sync) {
  std::string upper = text;
  for (char& c : upper) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  if (upper == "FULL") *sync = DiskSync::kFull;
  else if (upper == "NORMAL") *sync = DiskSync::kNormal;
  else if (upper == "OFF") *sync = DiskSync::kOff;
  else return false;
  return true;
}

std::string SchemaInfo::Describe() const {
  const bool is_4x = descriptors_have_type || user_version >= kFirstUserVersion4x;
  return std::string(is_4x ? "4.x-style" : "3.8-style") + " (user_version " +
         std::to_string(user_version) + ")";
}

struct Database::Impl {
  std::string path;
  bool read_only = false;
  DatabaseOptions options;
  sqlite3* db = nullptr;
  SchemaInfo schema;
  bool write_nulls_for_unset = false;  // 4.x convention
  bool in_transaction = false;
  std::vector<std::string> tables;  // as found when opening
  std::function<void(int)> on_commit_to_log;  // see HandOverLogFolding

  // Prepared on first use, then reused.
  std::unique_ptr<SqliteStatement> image_name, keypoints, descriptors, num_keypoints,
      num_descriptors, matches, geometry, write_matches, write_geometry, write_camera,
      write_image, write_keypoints, write_descriptors, keypoint_columns, record_empty_pairs,
      delete_matches, delete_geometry;
  bool empty_pairs_table_ready = false;  // kEmptyPairsTable created by this connection
  // WriteMatchesRows / WriteTwoViewGeometryRows: kRowsPerStatement rows each.
  std::unique_ptr<SqliteStatement> write_matches_rows, write_geometry_rows;

  // Asks the file, not the list read when opening: another connection (or
  // this one) may have created the table since.
  bool HasTableNow(const std::string& name) {
    SqliteStatement s(db, "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?");
    s.BindText(1, name);
    return s.Step();
  }

  ~Impl() {
    if (db == nullptr) return;
    if (in_transaction) sqlite3_exec(db, "ROLLBACK", nullptr, nullptr, nullptr);
    // close_v2 waits for the statements finalized right after this body.
    sqlite3_close_v2(db);
  }

  SqliteStatement& Prepared(std::unique_ptr<SqliteStatement>& slot, const std::string& sql) {
    if (!slot) slot = std::make_unique<SqliteStatement>(db, sql);
    return *slot;
  }

  void RequireWritable() const {
    if (read_only) throw DatabaseError("database opened read-only: " + path);
  }

  // "image 3 (a.jpg)" for messages.
  std::string ImageLabel(image_t image_id) {
    StatementScope s(Prepared(image_name, "SELECT name FROM images WHERE image_id = ?"));
    s->BindInt64(1, image_id);
    const std::string name = s->Step() ? s->ColumnText(0) : std::string("not in table images");
    return "image " + std::to_string(image_id) + " (" + name + ")";
  }

  std::vector<std::string> TableNames() {
    // The first read of the file: a non-SQLite file is reported here.
    sqlite3_stmt* raw = nullptr;
    int rc = sqlite3_prepare_v2(db, "SELECT name FROM sqlite_master WHERE type = 'table'", -1,
                                &raw, nullptr);
    std::vector<std::string> names;
    while (rc == SQLITE_OK || rc == SQLITE_ROW) {
      rc = sqlite3_step(raw);
      if (rc == SQLITE_ROW) {
        names.emplace_back(reinterpret_cast<const char*>(sqlite3_column_text(raw, 0)));
      }
    }
    const int code = sqlite3_errcode(db);
    const std::string message = sqlite3_errmsg(db);
    sqlite3_finalize(raw);
    if (rc == SQLITE_DONE) return names;
    if (code == SQLITE_NOTADB) throw DatabaseError("not a SQLite database: " + path);
    if (code == SQLITE_CORRUPT) {
      throw DatabaseError("database " + path + " is damaged (" + message +
                          "); PRAGMA integrity_check tells more");
    }
    if (code == SQLITE_CANTOPEN || code == SQLITE_READONLY) {
      // A WAL database needs its -wal and -shm files beside it.
      throw DatabaseError("cannot read database " + path + ": " + message +
                          " (its directory must be writable for SQLite's -wal/-shm files)");
    }
    if (code == SQLITE_BUSY) {
      throw DatabaseError("cannot read database " + path + ": " + message +
                          " (another process held the lock for longer than the busy timeout)");
    }
    throw DatabaseError("cannot read database " + path + ": " + message);
  }

  bool has_table(const std::string& name) const {
    return std::find(tables.begin(), tables.end(), name) != tables.end();
  }

  void RequireTable(const std::string& table) const {
    if (!has_table(table)) {
      throw DatabaseError("database " + path + " has no table '" + table +
                          "' (is it a COLMAP database with extracted features?)");
    }
  }

  bool TableHasColumn(const std::string& table, const std::string& column) {
    SqliteStatement s(db, "PRAGMA table_info(" + table + ")");
    while (s.Step()) {
      if (s.ColumnText(1) == column) return true;
    }
    return false;
  }

  void Open() {
    std::error_code error;
    if (!std::filesystem::exists(path, error)) {
      throw DatabaseError("database file not found: " + path);
    }
    if (std::filesystem::is_directory(path, error)) {
      throw DatabaseError("not a SQLite database: " + path + " is a directory");
    }
    // Readers open read-write too and are made query-only below: SQLite
    // deletes a WAL database's -wal and -shm files when the last connection
    // closes, but only a connection that may write can, so a run whose reader
    // closed after its writer left both files beside the database. A
    // write-protected file still opens (read-only) for reading.
    const int flags = SQLITE_OPEN_READWRITE | (options.one_thread_at_a_time ? SQLITE_OPEN_NOMUTEX : 0);
    if (sqlite3_open_v2(path.c_str(), &db, flags, nullptr) != SQLITE_OK) {
      const std::string message = db != nullptr ? sqlite3_errmsg(db) : "out of memory";
      throw DatabaseError("cannot open database " + path + ": " + message);
    }
    sqlite3_busy_timeout(db, std::max(0, options.busy_timeout_ms));
    // Nothing can be written through a reader (SQLITE_READONLY otherwise).
    if (read_only) ExecuteSql(db, "PRAGMA query_only = 1");
    if (!read_only && options.cache_mib > 0) {
      ExecuteSql(db, "PRAGMA cache_size = -" + std::to_string(static_cast<int64_t>(options.cache_mib) * 1024));
    }
    if (!read_only && options.disk_sync != DiskSync::kFull) {
      ExecuteSql(db, options.disk_sync == DiskSync::kNormal ? "PRAGMA synchronous = NORMAL" : "PRAGMA synchronous = OFF");
    }
    // SQLite silently opens a write-protected file read-only; say so now
    // rather than after matching everything.
    if (!read_only && sqlite3_db_readonly(db, "main") == 1) {
      throw DatabaseError("database " + path +
                          " is read-only (file permissions); cashash needs to write matches");
    }
    if (!read_only) {
      // SQLite creates its journal (-journal or -wal/-shm) beside the file: a
      // write-protected directory would fail the first commit, after matching.
      const std::filesystem::path absolute = std::filesystem::absolute(path, error);
      const std::string directory = absolute.parent_path().string();
      if (!error && access(directory.c_str(), W_OK) != 0) {
        throw DatabaseError("the directory " + directory + " of database " + path +
                            " is not writable; SQLite creates its journal files there");
      }
    }

    tables = TableNames();
    std::vector<std::string> required = {"cameras", "images", "keypoints", "descriptors"};
    if (!read_only) {
      required.push_back("matches");
      required.push_back("two_view_geometries");
    }
    for (const std::string& table : required) RequireTable(table);

    {
      SqliteStatement version(db, "PRAGMA user_version");
      schema.user_version = version.Step() ? static_cast<int>(version.ColumnInt64(0)) : 0;
    }
    schema.descriptors_have_type = TableHasColumn("descriptors", "type");
    schema.two_view_has_camera_columns =
        has_table("two_view_geometries") && TableHasColumn("two_view_geometries", "camera1") &&
        TableHasColumn("two_view_geometries", "camera2");
    schema.has_frames = has_table("frames");
    write_nulls_for_unset =
        schema.descriptors_have_type || schema.user_version >= kFirstUserVersion4x;

    if (!read_only) {
      // A per-connection setting, not the schema nor the journal mode (COLMAP's
      // WAL stays). With WAL a commit then needs no fsync; a crash can lose
      // the last commits, never corrupt the file.
      ExecuteSql(db, "PRAGMA synchronous = NORMAL");
    }
  }

  // Binds a matches row's 4 parameters after `first - 1`. `swapped`
  // receives the blob when the pair is stored in the other order (bound
  // from there: alive until the statement ran).
  static void BindMatches(SqliteStatement& s, int first, image_t image_id1, image_t image_id2,
                          const FeatureMatches& matches, std::vector<uint32_t>& swapped) {
    const bool swap = SwapImagePair(image_id1, image_id2);
    s.BindInt64(first, static_cast<int64_t>(ImagePairToPairId(image_id1, image_id2)));
    s.BindInt64(first + 1, static_cast<int64_t>(matches.size()));
    s.BindInt64(first + 2, 2);
    if (swap) {
      swapped = EncodeMatches(matches, true);
      s.BindBlob(first + 3, swapped.data(), swapped.size() * sizeof(uint32_t));
    } else {
      // In storage order the matches are the blob's bytes: bound in place.
      s.BindBlob(first + 3, MatchesAsStored(matches), matches.size() * 2 * sizeof(uint32_t));
    }
  }

  // Binds a two_view_geometries row's 10 parameters after `first - 1`.
  // `inverted` receives the geometry when the pair is stored in the other
  // order and `matrices` the encoded matrices (both alive until the
  // statement ran).
  void BindGeometryRow(SqliteStatement& s, int first, image_t image_id1, image_t image_id2,
                       const TwoViewGeometry& geometry, TwoViewGeometry& inverted,
                       std::array<std::array<double, 9>, 3>& matrices) {
    // What is unset is decided on the caller's geometry, before inverting.
    const bool F_set = !IsZero(geometry.F);
    const bool E_set = !IsZero(geometry.E);
    const bool H_set = !IsZero(geometry.H);
    const bool pose_set = !PoseIsUnset(geometry);
    const bool swap = SwapImagePair(image_id1, image_id2);
    if (swap) inverted = geometry.Inverted();
    BindGeometry(s, first, ImagePairToPairId(image_id1, image_id2), swap ? inverted : geometry, F_set, E_set, H_set,
                 pose_set, matrices);
  }

  void BindGeometry(SqliteStatement& s, int first, pair_t pair_id, const TwoViewGeometry& stored,
                    bool F_set, bool E_set, bool H_set, bool pose_set,
                    std::array<std::array<double, 9>, 3>& matrices) {
    const int o = first - 1;
    s.BindInt64(o + 1, static_cast<int64_t>(pair_id));
    s.BindInt64(o + 2, static_cast<int64_t>(stored.inlier_matches.size()));
    s.BindInt64(o + 3, 2);
    s.BindBlob(o + 4, MatchesAsStored(stored.inlier_matches), stored.inlier_matches.size() * 2 * sizeof(uint32_t));
    s.BindInt64(o + 5, stored.config);

    // 3.8 writes no geometry at all for pairs without inliers.
    const bool legacy_empty = !write_nulls_for_unset && stored.inlier_matches.empty();
    const Eigen::Matrix3d* sources[3] = {&stored.F, &stored.E, &stored.H};
    const bool set[3] = {F_set, E_set, H_set};
    for (int i = 0; i < 3; ++i) {
      const bool write_null = legacy_empty || (write_nulls_for_unset && !set[i]);
      if (write_null) {
        s.BindNull(o + 6 + i);
        continue;
      }
      matrices[i] = set[i] ? EncodeMatrix3d(*sources[i]) : std::array<double, 9>{};
      s.BindBlob(o + 6 + i, matrices[i].data(), sizeof(matrices[i]));
    }
    if (legacy_empty || (write_nulls_for_unset && !pose_set)) {
      s.BindNull(o + 9);
      s.BindNull(o + 10);
    } else {
      s.BindBlob(o + 9, stored.qvec.data(), 4 * sizeof(double));
      s.BindBlob(o + 10, stored.tvec.data(), 3 * sizeof(double));
    }
  }
};

Database::Database(const std::string& path, bool read_only, const DatabaseOptions& options)
    : impl_(std::make_unique<Impl>()) {
  impl_->path = path;
  impl_->read_only = read_only;
  impl_->options = options;
  impl_->Open();
}

Database::~Database() = default;

const SchemaInfo& Database::schema() const { return impl_->schema; }

bool Database::HasTable(const std::string& table) const { return impl_->has_table(table); }

bool Database::HasColumn(const std::string& table, const std::string& column) const {
  return impl_->has_table(table) && impl_->TableHasColumn(table, column);
}

void Database::UseStatement(const std::string& sql, const std::function<void(SqliteStatement&)>& use) const {
  SqliteStatement statement(impl_->db, sql);
  use(statement);
}
const std::string& Database::path() const { return impl_->path; }

std::vector<Camera> Database::ReadAllCameras() const {
  SqliteStatement s(impl_->db,
                    "SELECT camera_id, model, width, height, params, prior_focal_length "
                    "FROM cameras ORDER BY camera_id");
  std::vector<Camera> cameras;
  while (s.Step()) {
    Camera camera;
    camera.camera_id = static_cast<camera_t>(s.ColumnInt64(0));
    camera.model_id = static_cast<int>(s.ColumnInt64(1));
    camera.width = static_cast<uint64_t>(s.ColumnInt64(2));
    camera.height = static_cast<uint64_t>(s.ColumnInt64(3));
    const size_t num_bytes = s.ColumnBytes(4);
    if (num_bytes % sizeof(double) != 0) {
      throw DatabaseError("params of camera " + std::to_string(camera.camera_id) +
                          ": blob size " + std::to_string(num_bytes) +
                          " is not a multiple of 8 (float64 values)");
    }
    camera.params.resize(num_bytes / sizeof(double));
    if (num_bytes > 0) std::memcpy(camera.params.data(), s.ColumnBlob(4), num_bytes);
    camera.has_prior_focal_length = s.ColumnInt64(5) != 0;
    cameras.push_back(std::move(camera));
  }
  return cameras;
}

std::vector<Image> Database::ReadAllImages() const {
  SqliteStatement s(impl_->db, "SELECT image_id, name, camera_id FROM images ORDER BY image_id");
  std::vector<Image> images;
  while (s.Step()) {
    Image image;
    image.image_id = static_cast<image_t>(s.ColumnInt64(0));
    image.name = s.ColumnText(1);
    image.camera_id = static_cast<camera_t>(s.ColumnInt64(2));
    images.push_back(std::move(image));
  }
  return images;
}

Keypoints Database::ReadKeypoints(image_t image_id) const {
  StatementScope s(impl_->Prepared(impl_->keypoints,
                                   "SELECT rows, cols, data FROM keypoints WHERE image_id = ?"));
  s->BindInt64(1, image_id);
  if (!s->Step()) return {};  // no row: an image without features
  return DecodeKeypoints(MatrixBlobAt(*s, 0), "keypoints of " + impl_->ImageLabel(image_id));
}

FeatureDescriptors Database::ReadDescriptors(image_t image_id) const {
  const bool typed = impl_->schema.descriptors_have_type;
  StatementScope s(impl_->Prepared(
      impl_->descriptors,
      typed ? "SELECT rows, cols, data, type FROM descriptors WHERE image_id = ?"
            : "SELECT rows, cols, data FROM descriptors WHERE image_id = ?"));
  s->BindInt64(1, image_id);
  if (!s->Step()) return {};
  if (typed) {
    const int64_t type = s->ColumnInt64(3);
    if (type != kSiftDescriptorType) {
      throw DatabaseError("descriptors of " + impl_->ImageLabel(image_id) +
                          ": descriptor type " + DescriptorTypeName(type) + " (" +
                          std::to_string(type) + ") is not supported; extract SIFT features");
    }
  }
  return DecodeSiftDescriptors(MatrixBlobAt(*s, 0),
                               "descriptors of " + impl_->ImageLabel(image_id));
}

size_t Database::NumKeypoints(image_t image_id) const {
  StatementScope s(
      impl_->Prepared(impl_->num_keypoints, "SELECT rows FROM keypoints WHERE image_id = ?"));
  s->BindInt64(1, image_id);
  return s->Step() ? static_cast<size_t>(std::max<int64_t>(s->ColumnInt64(0), 0)) : 0;
}

size_t Database::NumDescriptors(image_t image_id) const {
  StatementScope s(
      impl_->Prepared(impl_->num_descriptors, "SELECT rows FROM descriptors WHERE image_id = ?"));
  s->BindInt64(1, image_id);
  return s->Step() ? static_cast<size_t>(std::max<int64_t>(s->ColumnInt64(0), 0)) : 0;
}

void Database::ForEachCompletedPairId(const std::function<void(pair_t)>& visit) const {
  // A read-only connection opens without the match tables.
  impl_->RequireTable("matches");
  impl_->RequireTable("two_view_geometries");
  // Both tables in pair_id order (their INTEGER PRIMARY KEY: a plain scan,
  // no sort), merged here: one pass over each, no lookup per row.
  SqliteStatement matches(impl_->db, "SELECT pair_id FROM matches ORDER BY pair_id");
  SqliteStatement geometries(impl_->db, "SELECT pair_id FROM two_view_geometries ORDER BY pair_id");
  bool more_matches = matches.Step(), more_geometries = geometries.Step();
  while (more_matches && more_geometries) {
    const int64_t m = matches.ColumnInt64(0), g = geometries.ColumnInt64(0);
    if (m == g) visit(static_cast<pair_t>(m));
    if (m <= g) more_matches = matches.Step();
    if (g <= m) more_geometries = geometries.Step();
  }
  if (impl_->HasTableNow(kEmptyPairsTable)) {
    SqliteStatement empty(impl_->db, std::string("SELECT rowid, data FROM ") + kEmptyPairsTable);
    while (empty.Step()) {
      DecodePairIdRuns(empty.ColumnBlob(1), empty.ColumnBytes(1),
                       std::string(kEmptyPairsTable) + " row " + std::to_string(empty.ColumnInt64(0)),
                       [&](pair_t first, pair_t last) {
                         for (pair_t id = first; id <= last; ++id) visit(id);
                       });
    }
  }
}

std::unordered_set<pair_t> Database::ReadCompletedPairIds() const {
  std::unordered_set<pair_t> pair_ids;
  ForEachCompletedPairId([&](pair_t id) { pair_ids.insert(id); });
  return pair_ids;
}

void Database::RecordEmptyPairs(const std::vector<pair_t>& pair_ids) {
  impl_->RequireWritable();
  if (pair_ids.empty()) return;
  if (!impl_->empty_pairs_table_ready) {
    ExecuteSql(impl_->db, std::string("CREATE TABLE IF NOT EXISTS ") + kEmptyPairsTable +
                              " (chunk_id INTEGER PRIMARY KEY NOT NULL, num_pairs INTEGER NOT NULL, data BLOB)");
    impl_->empty_pairs_table_ready = true;
  }
  const std::vector<uint8_t> runs = EncodePairIdRuns(pair_ids);
  StatementScope s(impl_->Prepared(impl_->record_empty_pairs, std::string("INSERT INTO ") + kEmptyPairsTable +
                                                                 "(num_pairs, data) VALUES (?, ?)"));
  s->BindInt64(1, static_cast<int64_t>(pair_ids.size()));
  s->BindBlob(2, runs.data(), runs.size());
  s->Execute();
}

void Database::DeleteMatchesAndGeometry(image_t image_id1, image_t image_id2) {
  impl_->RequireWritable();
  const int64_t pair_id = static_cast<int64_t>(ImagePairToPairId(image_id1, image_id2));
  StatementScope m(impl_->Prepared(impl_->delete_matches, "DELETE FROM matches WHERE pair_id = ?"));
  m->BindInt64(1, pair_id);
  m->Execute();
  DeleteTwoViewGeometry(image_id1, image_id2);
}

void Database::DeleteTwoViewGeometry(image_t image_id1, image_t image_id2) {
  impl_->RequireWritable();
  const int64_t pair_id = static_cast<int64_t>(ImagePairToPairId(image_id1, image_id2));
  StatementScope g(impl_->Prepared(impl_->delete_geometry, "DELETE FROM two_view_geometries WHERE pair_id = ?"));
  g->BindInt64(1, pair_id);
  g->Execute();
}

FeatureMatches Database::ReadMatches(image_t image_id1, image_t image_id2) const {
  const pair_t pair_id = ImagePairToPairId(image_id1, image_id2);
  StatementScope s(impl_->Prepared(impl_->matches,
                                   "SELECT rows, cols, data FROM matches WHERE pair_id = ?"));
  s->BindInt64(1, static_cast<int64_t>(pair_id));
  if (!s->Step()) return {};
  return DecodeMatches(MatrixBlobAt(*s, 0), SwapImagePair(image_id1, image_id2),
                       "matches of pair " + std::to_string(pair_id));
}

TwoViewGeometry Database::ReadTwoViewGeometry(image_t image_id1, image_t image_id2) const {
  const pair_t pair_id = ImagePairToPairId(image_id1, image_id2);
  StatementScope s(impl_->Prepared(
      impl_->geometry,
      "SELECT rows, cols, data, config, F, E, H, qvec, tvec FROM two_view_geometries "
      "WHERE pair_id = ?"));
  s->BindInt64(1, static_cast<int64_t>(pair_id));
  TwoViewGeometry stored;
  if (!s->Step()) return stored;
  const std::string owner = "two_view_geometries of pair " + std::to_string(pair_id);
  // Stored in the order of the smaller image id, hence no swap here.
  stored.inlier_matches = DecodeMatches(MatrixBlobAt(*s, 0), false, owner);
  stored.config = static_cast<int>(s->ColumnInt64(3));
  stored.F = DecodeMatrix3d(s->ColumnBlob(4), s->ColumnBytes(4), owner + ", F");
  stored.E = DecodeMatrix3d(s->ColumnBlob(5), s->ColumnBytes(5), owner + ", E");
  stored.H = DecodeMatrix3d(s->ColumnBlob(6), s->ColumnBytes(6), owner + ", H");
  stored.qvec = DecodeVector<4>(s->ColumnBlob(7), s->ColumnBytes(7),
                                Eigen::Vector4d(1, 0, 0, 0), owner + ", qvec");
  stored.tvec = DecodeVector<3>(s->ColumnBlob(8), s->ColumnBytes(8), Eigen::Vector3d::Zero(),
                                owner + ", tvec");
  if (!SwapImagePair(image_id1, image_id2)) return stored;
  TwoViewGeometry inverted = stored.Inverted();
  // Unset (zero) matrices stay unset whatever inverting a zero H yields.
  if (IsZero(stored.F)) inverted.F.setZero();
  if (IsZero(stored.E)) inverted.E.setZero();
  if (IsZero(stored.H)) inverted.H.setZero();
  return inverted;
}

namespace {

constexpr const char* kInsertMatches = "INSERT OR REPLACE INTO matches(pair_id, rows, cols, data) VALUES ";
constexpr const char* kMatchesValues = "(?, ?, ?, ?)";
// camera1 / camera2 (4.x) are left out of the column list: INSERT OR
// REPLACE then stores NULL, as COLMAP does for fixed-intrinsics geometries.
constexpr const char* kInsertGeometries =
    "INSERT OR REPLACE INTO two_view_geometries(pair_id, rows, cols, data, config, F, E, H, qvec, tvec) VALUES ";
constexpr const char* kGeometryValues = "(?, ?, ?, ?, ?, ?, ?, ?, ?, ?)";

// Rows per statement of the *Rows writes: at 64, a statement's own cost is
// small beside its rows', and 640 parameters stay far below SQLite's limit.
constexpr size_t kRowsPerStatement = 64;

std::string RepeatedValues(const char* insert, const char* values, size_t rows) {
  std::string sql = insert;
  for (size_t k = 0; k < rows; ++k) sql += (k == 0 ? "" : ", ") + std::string(values);
  return sql;
}

}  // namespace

void Database::WriteMatches(image_t image_id1, image_t image_id2, const FeatureMatches& matches) {
  impl_->RequireWritable();
  SqliteStatement& s = impl_->Prepared(impl_->write_matches, RepeatedValues(kInsertMatches, kMatchesValues, 1));
  // Every parameter is bound again below: a reset, no clearing.
  s.ResetKeepingBindings();
  std::vector<uint32_t> swapped;
  Impl::BindMatches(s, 1, image_id1, image_id2, matches, swapped);
  s.Execute();
}

void Database::WriteTwoViewGeometry(image_t image_id1, image_t image_id2,
                                    const TwoViewGeometry& geometry) {
  impl_->RequireWritable();
  SqliteStatement& s =
      impl_->Prepared(impl_->write_geometry, RepeatedValues(kInsertGeometries, kGeometryValues, 1));
  s.ResetKeepingBindings();  // BindGeometryRow binds every parameter
  TwoViewGeometry inverted;
  std::array<std::array<double, 9>, 3> matrices{};
  impl_->BindGeometryRow(s, 1, image_id1, image_id2, geometry, inverted, matrices);
  s.Execute();
}

void Database::WriteMatchesRows(const std::vector<PairRowsRef>& pairs) {
  impl_->RequireWritable();
  size_t k = 0;
  if (pairs.size() >= kRowsPerStatement) {
    SqliteStatement& s = impl_->Prepared(impl_->write_matches_rows,
                                         RepeatedValues(kInsertMatches, kMatchesValues, kRowsPerStatement));
    std::vector<std::vector<uint32_t>> swapped(kRowsPerStatement);
    for (; k + kRowsPerStatement <= pairs.size(); k += kRowsPerStatement) {
      s.ResetKeepingBindings();
      for (size_t r = 0; r < kRowsPerStatement; ++r) {
        const PairRowsRef& p = pairs[k + r];
        Impl::BindMatches(s, static_cast<int>(4 * r + 1), p.image_id1, p.image_id2, *p.matches, swapped[r]);
      }
      s.Execute();
    }
  }
  for (; k < pairs.size(); ++k) WriteMatches(pairs[k].image_id1, pairs[k].image_id2, *pairs[k].matches);
}

void Database::WriteTwoViewGeometryRows(const std::vector<PairRowsRef>& pairs) {
  impl_->RequireWritable();
  size_t k = 0;
  if (pairs.size() >= kRowsPerStatement) {
    SqliteStatement& s = impl_->Prepared(impl_->write_geometry_rows,
                                         RepeatedValues(kInsertGeometries, kGeometryValues, kRowsPerStatement));
    std::vector<TwoViewGeometry> inverted(kRowsPerStatement);
    std::vector<std::array<std::array<double, 9>, 3>> matrices(kRowsPerStatement);
    for (; k + kRowsPerStatement <= pairs.size(); k += kRowsPerStatement) {
      s.ResetKeepingBindings();
      for (size_t r = 0; r < kRowsPerStatement; ++r) {
        const PairRowsRef& p = pairs[k + r];
        impl_->BindGeometryRow(s, static_cast<int>(10 * r + 1), p.image_id1, p.image_id2, *p.geometry, inverted[r],
                               matrices[r]);
      }
      s.Execute();
    }
  }
  for (; k < pairs.size(); ++k) WriteTwoViewGeometry(pairs[k].image_id1, pairs[k].image_id2, *pairs[k].geometry);
}

void Database::ClearMatchesAndGeometries() {
  impl_->RequireWritable();
  const bool own_transaction = !impl_->in_transaction;
  if (own_transaction) BeginTransaction();
  try {
    ExecuteSql(impl_->db, "DELETE FROM matches");
    ExecuteSql(impl_->db, "DELETE FROM two_view_geometries");
    if (impl_->HasTableNow(kEmptyPairsTable)) ExecuteSql(impl_->db, std::string("DELETE FROM ") + kEmptyPairsTable);
  } catch (...) {
    if (own_transaction) Rollback();
    throw;
  }
  if (own_transaction) Commit();
}

camera_t Database::WriteCamera(const Camera& camera) {
  impl_->RequireWritable();
  StatementScope s(impl_->Prepared(
      impl_->write_camera,
      "INSERT INTO cameras(model, width, height, params, prior_focal_length) VALUES (?, ?, ?, ?, ?)"));
  s->BindInt64(1, camera.model_id);
  s->BindInt64(2, static_cast<int64_t>(camera.width));
  s->BindInt64(3, static_cast<int64_t>(camera.height));
  s->BindBlob(4, camera.params.data(), camera.params.size() * sizeof(double));
  s->BindInt64(5, camera.has_prior_focal_length ? 1 : 0);
  s->Execute();
  return static_cast<camera_t>(sqlite3_last_insert_rowid(impl_->db));
}

image_t Database::WriteImage(const std::string& name, camera_t camera_id) {
  impl_->RequireWritable();
  StatementScope s(impl_->Prepared(impl_->write_image, "INSERT INTO images(name, camera_id) VALUES (?, ?)"));
  s->BindText(1, name);
  s->BindInt64(2, camera_id);
  s->Execute();
  return static_cast<image_t>(sqlite3_last_insert_rowid(impl_->db));
}

void Database::WriteKeypoints(image_t image_id, const Keypoints& keypoints, int num_columns) {
  impl_->RequireWritable();
  const std::vector<float> values = EncodeKeypoints(keypoints, num_columns);
  StatementScope s(impl_->Prepared(
      impl_->write_keypoints, "INSERT OR REPLACE INTO keypoints(image_id, rows, cols, data) VALUES (?, ?, ?, ?)"));
  s->BindInt64(1, image_id);
  s->BindInt64(2, static_cast<int64_t>(keypoints.size()));
  s->BindInt64(3, num_columns);
  s->BindBlob(4, values.data(), values.size() * sizeof(float));
  s->Execute();
}

void Database::WriteDescriptors(image_t image_id, const FeatureDescriptors& descriptors) {
  impl_->RequireWritable();
  const bool typed = impl_->schema.descriptors_have_type;
  StatementScope s(impl_->Prepared(
      impl_->write_descriptors,
      typed ? "INSERT OR REPLACE INTO descriptors(image_id, rows, cols, data, type) VALUES (?, ?, ?, ?, ?)"
            : "INSERT OR REPLACE INTO descriptors(image_id, rows, cols, data) VALUES (?, ?, ?, ?)"));
  s->BindInt64(1, image_id);
  s->BindInt64(2, static_cast<int64_t>(descriptors.rows()));
  s->BindInt64(3, kDescriptorDim);
  s->BindBlob(4, descriptors.data.data(), descriptors.data.size());
  if (typed) s->BindInt64(5, kSiftDescriptorType);
  s->Execute();
}

int Database::KeypointColumns(image_t image_id) const {
  StatementScope s(
      impl_->Prepared(impl_->keypoint_columns, "SELECT cols FROM keypoints WHERE image_id = ?"));
  s->BindInt64(1, image_id);
  return s->Step() ? static_cast<int>(s->ColumnInt64(0)) : 0;
}

void Database::BeginTransaction() {
  if (impl_->in_transaction) {
    throw DatabaseError("a transaction is already open on " + impl_->path);
  }
  // IMMEDIATE takes the write lock now (waiting up to the busy timeout), so a
  // concurrent writer cannot make a later write fail halfway.
  ExecuteSql(impl_->db, impl_->read_only ? "BEGIN" : "BEGIN IMMEDIATE");
  impl_->in_transaction = true;
}

void Database::Commit() {
  if (!impl_->in_transaction) {
    throw DatabaseError("no transaction to commit on " + impl_->path);
  }
  ExecuteSql(impl_->db, "COMMIT");
  impl_->in_transaction = false;
}

size_t Database::CachedPageBytes() const {
  int used = 0;
  int highest = 0;
  if (sqlite3_db_status(impl_->db, SQLITE_DBSTATUS_CACHE_USED, &used, &highest, 0) != SQLITE_OK) return 0;
  return used > 0 ? static_cast<size_t>(used) : 0;
}

void Database::ReleaseCachedPages() { sqlite3_db_release_memory(impl_->db); }

void Database::Rollback() {
  if (!impl_->in_transaction) {
    throw DatabaseError("no transaction to roll back on " + impl_->path);
  }
  impl_->in_transaction = false;
  // SQLite may already have rolled back by itself (disk full, I/O error);
  // then there is nothing to undo and the caller's original error matters.
  if (sqlite3_get_autocommit(impl_->db) != 0) return;
  ExecuteSql(impl_->db, "ROLLBACK");
}

bool Database::UsesWriteAheadLog() const {
  SqliteStatement s(impl_->db, "PRAGMA journal_mode");
  return s.Step() && s.ColumnText(0) == "wal";
}

void Database::HandOverLogFolding(std::function<void(int logged_pages)> logged) {
  impl_->RequireWritable();
  impl_->on_commit_to_log = std::move(logged);
  // Replaces the hook through which SQLite folds the log itself.
  sqlite3_wal_hook(
      impl_->db,
      [](void* impl, sqlite3*, const char*, int pages) {
        static_cast<Impl*>(impl)->on_commit_to_log(pages);
        return SQLITE_OK;
      },
      impl_.get());
}

}  // namespace colmap
}  // namespace cashash
