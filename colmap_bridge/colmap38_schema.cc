#include "colmap_bridge/colmap38_schema.h"

#include <filesystem>
#include <sqlite3.h>

#include "colmap_bridge/database.h"
#include "colmap_bridge/sqlite_statement.h"

namespace cashash {
namespace colmap {
namespace {

// The columns, types and constraints of COLMAP 3.8's tables: pose priors
// still live in images, there are no rigs or frames, descriptors have no
// type column. sqlite_sequence appears with the first AUTOINCREMENT row.
const char* const kColmap38Tables[] = {
    "CREATE TABLE cameras (camera_id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, model INTEGER NOT NULL, "
    "width INTEGER NOT NULL, height INTEGER NOT NULL, params BLOB, prior_focal_length INTEGER NOT NULL)",
    "CREATE TABLE images (image_id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, name TEXT NOT NULL UNIQUE, "
    "camera_id INTEGER NOT NULL, prior_qw REAL, prior_qx REAL, prior_qy REAL, prior_qz REAL, prior_tx REAL, "
    "prior_ty REAL, prior_tz REAL, CONSTRAINT image_id_check CHECK(image_id >= 0 and image_id < 2147483647), "
    "FOREIGN KEY(camera_id) REFERENCES cameras(camera_id))",
    "CREATE UNIQUE INDEX index_name ON images(name)",
    "CREATE TABLE keypoints (image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, "
    "data BLOB, FOREIGN KEY(image_id) REFERENCES images(image_id) ON DELETE CASCADE)",
    "CREATE TABLE descriptors (image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, "
    "cols INTEGER NOT NULL, data BLOB, FOREIGN KEY(image_id) REFERENCES images(image_id) ON DELETE CASCADE)",
    "CREATE TABLE matches (pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, "
    "data BLOB)",
    "CREATE TABLE two_view_geometries (pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, "
    "cols INTEGER NOT NULL, data BLOB, config INTEGER NOT NULL, F BLOB, E BLOB, H BLOB, qvec BLOB, tvec BLOB)",
};

// Closes the connection however the function is left.
struct Connection {
  sqlite3* db = nullptr;
  ~Connection() { sqlite3_close_v2(db); }
};

void OpenForWriting(const std::string& path, int extra_flags, Connection* connection) {
  if (sqlite3_open_v2(path.c_str(), &connection->db, SQLITE_OPEN_READWRITE | extra_flags, nullptr) != SQLITE_OK) {
    const std::string message = connection->db != nullptr ? sqlite3_errmsg(connection->db) : "out of memory";
    throw DatabaseError("cannot create database " + path + ": " + message);
  }
}

}  // namespace

void CreateColmap38Database(const std::string& path) {
  std::error_code error;
  if (std::filesystem::exists(path, error)) {
    throw DatabaseError("database " + path + " exists already; a new database is written from scratch");
  }
  Connection connection;
  OpenForWriting(path, SQLITE_OPEN_CREATE, &connection);
  ExecuteSql(connection.db, "BEGIN");
  for (const char* sql : kColmap38Tables) ExecuteSql(connection.db, sql);
  ExecuteSql(connection.db, "PRAGMA user_version = " + std::to_string(kColmap38UserVersion));
  ExecuteSql(connection.db, "COMMIT");
}

void SetWalJournal(const std::string& path) {
  Connection connection;
  OpenForWriting(path, 0, &connection);
  // journal_mode answers with a row, which ExecuteSql discards.
  ExecuteSql(connection.db, "PRAGMA journal_mode = WAL");
}

}  // namespace colmap
}  // namespace cashash
