// Reading and writing COLMAP databases (SQLite), for databases created by
// COLMAP 3.8 and by COLMAP 4.x: the schema is detected when opening.
#pragma once

#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <unordered_set>
#include <vector>

#include "cashash/geometry/two_view_geometry.h"
#include "cashash/base/types.h"

struct sqlite3;

namespace cashash {
namespace colmap {

class SqliteStatement;

// Every error names the table, image or file at fault.
class DatabaseError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// cashash's own table of pairs decided empty (see RecordEmptyPairs).
constexpr const char* kEmptyPairsTable = "cashash_empty_pairs";

struct SchemaInfo {
  int user_version = 0;            // PRAGMA user_version
  bool descriptors_have_type = false;    // COLMAP >= 4.0
  bool two_view_has_camera_columns = false;  // unreleased main: camera1, camera2
  bool has_frames = false;         // COLMAP >= 3.12 (rigs/frames tables)
  // "3.8-style" or "4.x-style", for messages.
  std::string Describe() const;
};

// SQLite's PRAGMA synchronous of a writing connection: when it waits for
// the disk. Full is SQLite's default and the safe one.
enum class DiskSync {
  // Every commit is on disk before the next one starts: a power loss or an
  // operating-system crash loses nothing committed.
  kFull,
  // With the write-ahead log (COLMAP's databases): the log reaches the disk
  // when it is folded into the file, not at each commit. A power loss or an
  // OS crash may undo the last commits; the file stays valid and a rerun
  // matches those pairs again. A killed process loses nothing committed.
  kNormal,
  // Never waits for the disk (what COLMAP's own database connection uses).
  // A power loss or an OS crash may leave the file damaged.
  kOff,
};

// "FULL", "NORMAL", "OFF" (any case); false for anything else.
bool ParseDiskSync(const std::string& text, DiskSync* sync);

struct DatabaseOptions {
  // How long a connection waits for a lock another process holds (COLMAP's
  // GUI, another matcher) before a statement fails naming the busy timeout.
  int busy_timeout_ms = 60000;
  // Page cache of a writing connection in MiB; 0 keeps SQLite's 2 MiB. A
  // transaction whose changed pages fit writes each of them to the log once
  // at its commit; beyond the cache SQLite writes them early, and again when
  // they change again.
  int cache_mib = 0;
  DiskSync disk_sync = DiskSync::kFull;
  // The connection is used by one thread at a time (the caller makes sure):
  // SQLite then takes no lock of its own around each call.
  bool one_thread_at_a_time = false;
};

// One pair's results as WriteMatchesRows / WriteTwoViewGeometryRows take
// them: pointers to the caller's values, alive during the call.
struct PairRowsRef {
  image_t image_id1 = 0;
  image_t image_id2 = 0;
  const FeatureMatches* matches = nullptr;
  const TwoViewGeometry* geometry = nullptr;
};

class Database {
 public:
  // Opens an existing COLMAP database; throws DatabaseError if the file does
  // not exist, is not SQLite, or lacks a required table.
  explicit Database(const std::string& path, bool read_only = false, const DatabaseOptions& options = {});
  ~Database();
  Database(const Database&) = delete;
  Database& operator=(const Database&) = delete;

  const SchemaInfo& schema() const;
  const std::string& path() const;

  std::vector<Camera> ReadAllCameras() const;
  std::vector<Image> ReadAllImages() const;  // ordered by image_id

  // Keypoints with 2, 4 or 6 columns, converted to the 6-column form.
  Keypoints ReadKeypoints(image_t image_id) const;
  // uint8 x 128 SIFT descriptors; throws naming the image when the blob is
  // not that (float, other width, size mismatch, ALIKED type).
  FeatureDescriptors ReadDescriptors(image_t image_id) const;
  // Rows of the keypoints / descriptors tables for an image (0 if no row).
  size_t NumKeypoints(image_t image_id) const;
  size_t NumDescriptors(image_t image_id) const;

  // Pairs that already have both a matches and a two_view_geometries row,
  // and pairs recorded by RecordEmptyPairs (these are skipped on resume),
  // streamed: each id once or more (a pair with rows can be recorded empty
  // too), in no promised order. Memory does not grow with the table.
  void ForEachCompletedPairId(const std::function<void(pair_t)>& visit) const;
  // The same pairs collected in a set: for small databases and tests (at
  // 200 million pairs the set alone takes gigabytes; runs use
  // ReadCompletedPairs of completed_pairs.h).
  std::unordered_set<pair_t> ReadCompletedPairIds() const;

  // Records pairs that were matched and found no match, for runs that write
  // no rows for them (--write_empty_pairs 0): one row of the table
  // kEmptyPairsTable (created on first use; COLMAP ignores it) holding their
  // ids as runs (pair_id_runs.h). Lets a rerun skip them.
  void RecordEmptyPairs(const std::vector<pair_t>& pair_ids);
  // Removes a pair's rows from matches and two_view_geometries (a pair
  // matched again, now without matches, under --write_empty_pairs 0).
  void DeleteMatchesAndGeometry(image_t image_id1, image_t image_id2);
  // Removes a pair's two_view_geometries row (its matches rewritten without
  // verification under --overwrite: the old row describes other matches).
  void DeleteTwoViewGeometry(image_t image_id1, image_t image_id2);

  FeatureMatches ReadMatches(image_t image_id1, image_t image_id2) const;
  TwoViewGeometry ReadTwoViewGeometry(image_t image_id1, image_t image_id2) const;

  // Writes with COLMAP's conventions: keyed by pair_id, match columns swapped
  // and the geometry inverted when image_id1 > image_id2. Replaces an
  // existing row of the same pair.
  void WriteMatches(image_t image_id1, image_t image_id2, const FeatureMatches& matches);
  void WriteTwoViewGeometry(image_t image_id1, image_t image_id2, const TwoViewGeometry& geometry);
  // The same rows for many pairs, in their order, several pairs per
  // statement: a statement's cursor stays where the last row went, so rows
  // in pair-id order each land next to the one before, and the statement's
  // own cost is shared. Rows are bound in place, without copies, unless the
  // pair is stored in the other order.
  void WriteMatchesRows(const std::vector<PairRowsRef>& pairs);
  void WriteTwoViewGeometryRows(const std::vector<PairRowsRef>& pairs);

  // Removes every row of matches and two_view_geometries (--overwrite of an
  // exhaustive run).
  void ClearMatchesAndGeometries();

  // Rows of the feature tables, for databases that cashash itself creates
  // (generate_database). Cameras and images get the next free id, returned.
  camera_t WriteCamera(const Camera& camera);
  image_t WriteImage(const std::string& name, camera_t camera_id);
  // Stored with `num_columns` 2, 4 or 6 float32 columns (see EncodeKeypoints).
  void WriteKeypoints(image_t image_id, const Keypoints& keypoints, int num_columns);
  // uint8 x 128; SIFT type (0) where the table has a type column.
  void WriteDescriptors(image_t image_id, const FeatureDescriptors& descriptors);
  // Float32 columns (2, 4 or 6) of an image's keypoints row; 0 when it has none.
  int KeypointColumns(image_t image_id) const;

  // For tables this class does not model (pose priors, rig frames:
  // position_priors.h, image_frames.h): whether the file had `table` when
  // it was opened, whether `table` has `column`, and a statement prepared on
  // this connection from `sql` for `use` to bind, step and read (finalized
  // when it returns or throws).
  bool HasTable(const std::string& table) const;
  bool HasColumn(const std::string& table, const std::string& column) const;
  void UseStatement(const std::string& sql, const std::function<void(SqliteStatement&)>& use) const;

  void BeginTransaction();
  void Commit();
  void Rollback();
  // Bytes of pages this connection's cache holds.
  size_t CachedPageBytes() const;
  // Gives back the pages this connection's cache holds unchanged (all of
  // them between transactions); the next statements read what they need
  // again.
  void ReleaseCachedPages();

  // True when the file keeps SQLite's write-ahead log (COLMAP's databases do).
  bool UsesWriteAheadLog() const;
  // Hands the folding of the write-ahead log to someone else
  // (WalCheckpointer): this connection's commits stop folding it themselves
  // (SQLite's default: the commit that takes the log past 1,000 pages), and
  // after each commit `logged` gets the pages the log now holds.
  void HandOverLogFolding(std::function<void(int logged_pages)> logged);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace colmap
}  // namespace cashash
