// Folds SQLite's write-ahead log into the database file on a thread and a
// connection of its own, while the pipeline's writer keeps appending to it.
//
// Why: by default the commit that takes the log past 1,000 pages folds it
// itself, on the writer's thread: it reads the logged pages back, writes them
// into the file and waits for an fsync. Writing a 1,000-image run's million
// rows, that was a third of the writer's time (perf: pwrite, pread and
// fdatasync under the checkpoint), and at that size guided matching waits on
// the writer. A passive checkpoint never takes the write lock, so the writer
// does not wait for it. SQLite starts the log over only when a transaction
// begins with the whole log folded; a writer that commits back to back never
// sees that, so it calls CatchUp() when the log has grown past a bound.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <mutex>
#include <string>
#include <thread>

struct sqlite3;

namespace cashash {
namespace colmap {

class WalCheckpointer {
 public:
  // Opens a connection to the database. Throws DatabaseError if it cannot.
  explicit WalCheckpointer(const std::string& database_path);
  // Runs a last checkpoint of what was committed, then closes its connection.
  ~WalCheckpointer();
  WalCheckpointer(const WalCheckpointer&) = delete;
  WalCheckpointer& operator=(const WalCheckpointer&) = delete;

  // Something was committed: checkpoint soon. Calls that come while a
  // checkpoint runs are folded into the next one.
  void Nudge();
  // Blocks until a checkpoint that began after this call has ended. Called
  // between two transactions, with nothing committed meanwhile, that
  // checkpoint folds the whole log (unless a reader holds part of it), and
  // the next transaction starts the log over.
  void CatchUp();

  // Checkpoints run so far (one that finds the log busy, a reader or the
  // writer's restart holding a lock it needs, counts too; the next retries).
  size_t checkpoints() const;

 private:
  void Loop();

  sqlite3* db_ = nullptr;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable ended_;
  bool pending_ = false;
  bool stop_ = false;
  size_t started_ = 0;
  size_t checkpoints_ = 0;
  std::thread thread_;
};

}  // namespace colmap
}  // namespace cashash
