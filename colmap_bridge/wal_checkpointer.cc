#include "colmap_bridge/wal_checkpointer.h"

#include <sqlite3.h>

#include "colmap_bridge/database.h"

namespace cashash {
namespace colmap {

WalCheckpointer::WalCheckpointer(const std::string& database_path) {
  const auto fail = [&](const std::string& what) {
    const std::string message = db_ != nullptr ? sqlite3_errmsg(db_) : "out of memory";
    sqlite3_close_v2(db_);
    db_ = nullptr;
    throw DatabaseError("cannot " + what + " database " + database_path + " to fold its log: " + message);
  };
  if (sqlite3_open_v2(database_path.c_str(), &db_, SQLITE_OPEN_READWRITE, nullptr) != SQLITE_OK) fail("open");
  // This connection writes no rows; it must never fold the log on its own
  // schedule either.
  sqlite3_wal_autocheckpoint(db_, 0);
  // For the first read below, which a recovering or locking connection may
  // hold off for a moment; passive checkpoints never wait on it.
  sqlite3_busy_timeout(db_, 60000);
  // SQLite opens the file on the first statement; until then the connection
  // does not know the log exists and a checkpoint does nothing.
  if (sqlite3_exec(db_, "SELECT count(*) FROM sqlite_master", nullptr, nullptr, nullptr) != SQLITE_OK) fail("read");
  thread_ = std::thread([this] { Loop(); });
}

WalCheckpointer::~WalCheckpointer() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_one();
  thread_.join();
  sqlite3_close_v2(db_);
}

void WalCheckpointer::Nudge() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_ = true;
  }
  wake_.notify_one();
}

void WalCheckpointer::CatchUp() {
  std::unique_lock<std::mutex> lock(mutex_);
  const size_t wanted = started_ + 1;
  pending_ = true;
  wake_.notify_one();
  ended_.wait(lock, [&] { return checkpoints_ >= wanted; });
}

size_t WalCheckpointer::checkpoints() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return checkpoints_;
}

void WalCheckpointer::Loop() {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return pending_ || stop_; });
    const bool last = stop_;
    pending_ = false;
    ++started_;
    lock.unlock();
    // PASSIVE: copies what no reader still needs, takes no write lock and
    // never calls the busy handler, so the writer never waits on it. A busy
    // log is retried by the next checkpoint; any other failure (disk full,
    // I/O error) leaves the log as it is: the writer's commits stay valid in
    // it, and the last connection to close folds it.
    sqlite3_wal_checkpoint_v2(db_, nullptr, SQLITE_CHECKPOINT_PASSIVE, nullptr, nullptr);
    lock.lock();
    ++checkpoints_;
    ended_.notify_all();
    if (last) return;
  }
}

}  // namespace colmap
}  // namespace cashash
