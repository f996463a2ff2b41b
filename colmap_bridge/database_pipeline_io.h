// The matching pipeline's source and sink on a COLMAP database: features are
// read through one connection, results written through another in
// transactions of whole chunks, so that a stopped run leaves whole chunks
// only.
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "cashash/base/object_pool.h"
#include "cashash/pipeline/matching_pipeline.h"
#include "colmap_bridge/database.h"
#include "colmap_bridge/database_writer_lock.h"
#include "colmap_bridge/wal_checkpointer.h"

namespace cashash {
namespace colmap {

class DatabaseFeatureSource : public FeatureSource {
 public:
  // Reads the images and cameras tables; throws DatabaseError if an image
  // refers to a camera that does not exist or two images share a name.
  // `warning` hears about usable but suspicious data (a camera model
  // unknown to cashash, keypoints outside their image), one call at a time,
  // from the constructor and the loading threads; unset: "WARNING: ..."
  // lines on stderr. The runs pass their callbacks' warning.
  explicit DatabaseFeatureSource(const std::string& database_path,
                                 std::function<void(const std::string&)> warning = nullptr);

  const std::vector<Image>& images() const { return images_; }
  const Image& image(image_t image_id) const;

  // Throws DatabaseError naming the image when keypoints and descriptors
  // disagree in their number of rows or a keypoint is NaN / infinite; warns
  // once per image about keypoints outside the image (COLMAP uses them).
  // Any number of threads may call it at once: each call reads through a
  // connection of its own, from a pool opened as needed.
  ImageFeatures LoadFeatures(image_t image_id) override;
  const Camera& CameraOfImage(image_t image_id) const override;
  // Four: on the H200 machine one thread read 1,000 images of 8,192
  // features (1.2 GiB) in 0.9 s, mostly copying blobs out of SQLite's pages.
  int MaxConcurrentLoads() const override { return kConcurrentLoads; }
  static constexpr int kConcurrentLoads = 4;

  // The connection that read the images and cameras; LoadFeatures does not use it.
  Database& database() { return database_; }

 private:
  // Throws when the params do not fit a known model; warns for unknown models.
  void CheckCamera(const Camera& camera);
  void WarnAboutKeypointsOutside(image_t image_id, const Keypoints& keypoints);
  void Warn(const std::string& text);

  Database database_;
  ObjectPool<Database> readers_;  // LoadFeatures' connections, one per caller at a time
  std::vector<Image> images_;
  std::unordered_map<image_t, size_t> image_index_;
  std::unordered_map<camera_t, Camera> cameras_;
  std::function<void(const std::string&)> warning_;
  std::mutex warned_mutex_;
  std::unordered_set<image_t> warned_images_;
};

class DatabaseResultSink : public ResultSink {
 public:
  // What a chunk writes besides the pairs with matches.
  struct Options {
    bool write_two_view_geometries = true;
    // COLMAP writes a matches and a two_view_geometries row for every pair it
    // matched, also with no match (rows = 0). Off, pairs without a match get
    // no rows; their ids are recorded compactly (Database::RecordEmptyPairs)
    // so that a rerun skips them. COLMAP's own matchers do not read that
    // record and would match those pairs again.
    bool write_empty_pairs = true;
    // The pairs may have rows from an earlier run (--overwrite): a pair now
    // without a match has its old rows deleted when no rows are written for
    // it, and without write_two_view_geometries its old two_view_geometries
    // row goes (it verified other matches; a resumed run would skip the pair).
    bool replace_existing = false;
    // With a write-ahead log (COLMAP's databases): its size in pages at which
    // the writer waits for the checkpointer to fold it, so that the next
    // chunk starts it over. 16,384 pages are 64 MiB with COLMAP's 4 KiB
    // pages, 16 times SQLite's own bound, so that most chunks never wait.
    int log_pages_before_catch_up = 16384;
    // DatabaseOptions::busy_timeout_ms of the writer's connection.
    int busy_timeout_ms = DatabaseOptions().busy_timeout_ms;
    // A transaction takes the chunks that come until it has been open this
    // long, then commits after a whole chunk (0: one transaction per
    // chunk). Chunks of one row of block pairs share their images' key
    // ranges, so one commit writes the pages they share to the log once
    // instead of once per chunk. What a kill -9 loses is bounded by it:
    // the uncommitted chunks are matched again by the next run.
    double commit_seconds = 1.0;
    // A transaction also commits after the chunk that brings its rows'
    // blobs to this many MiB (0: no bound). Grouped by time alone, a fast
    // run's transaction grows past the log's catch-up bound: the commit
    // then writes it all to the log at once, and the writer waits for the
    // checkpointer to fold it, where smaller commits let the checkpointer
    // fold one transaction while the next is written. A quarter of
    // log_pages_before_catch_up keeps several commits between catch-ups.
    int commit_mib = 16;
    // DatabaseOptions::cache_mib of the writer's connection: room for a
    // transaction's changed pages, given back after a commit that leaves
    // more than kept_cache_mib in the cache.
    int cache_mib = 256;
    int kept_cache_mib = 16;
    // DatabaseOptions::disk_sync of the writer's connection (see DiskSync
    // for what each setting risks).
    DiskSync disk_sync = DiskSync::kFull;
  };

  // Throws DatabaseError when another cashash process writes to the same
  // database (see DatabaseWriterLock).
  DatabaseResultSink(const std::string& database_path, bool write_two_view_geometries);
  DatabaseResultSink(const std::string& database_path, const Options& options);
  // Commits what is written (Flush); a failure then rolls back the chunks
  // not yet committed, which the next run matches again.
  ~DatabaseResultSink() override;
  // Writes the chunk into the open transaction (opening one if needed),
  // rows sorted by pair id, table by table, through prepared statements,
  // from the one writer thread of the pipeline; commits when the
  // transaction is commit_seconds old. On failure the transaction's chunks
  // are rolled back.
  void WriteChunk(const std::vector<PairResult>& results) override;
  // Commits the open transaction, if any.
  void Flush() override;

  // Rows written to matches and two_view_geometries and committed so far.
  size_t rows_written() const { return rows_written_; }
  // Pairs recorded as empty instead of written (write_empty_pairs off), committed.
  size_t empty_pairs_recorded() const { return empty_pairs_recorded_; }
  // Transactions committed so far.
  size_t commits() const { return commits_; }

 private:
  void WriteRows(const std::vector<PairResult>& results);
  void Commit();

  DatabaseWriterLock lock_;  // taken before opening, released after closing
  Database database_;
  // Folds the log off the writer's thread; null for a rollback-journal file.
  // Declared after database_: stopped before the writer's connection closes.
  std::unique_ptr<WalCheckpointer> checkpointer_;
  Options options_;
  int logged_pages_ = 0;  // in the log after the last commit
  bool in_transaction_ = false;
  std::chrono::steady_clock::time_point transaction_start_;
  std::vector<size_t> order_;  // a chunk's rows by pair id, reused
  std::vector<PairRowsRef> rows_;  // the same, as written, reused
  std::vector<pair_t> empty_pairs_;  // reused
  size_t pending_rows_ = 0;          // in the open transaction
  size_t pending_bytes_ = 0;         // the same rows' blobs
  size_t pending_empty_pairs_ = 0;
  size_t rows_written_ = 0;
  size_t empty_pairs_recorded_ = 0;
  size_t commits_ = 0;
};

}  // namespace colmap
}  // namespace cashash
