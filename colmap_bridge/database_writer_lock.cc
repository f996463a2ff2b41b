// The lock is flock(2) on the database file itself, so no stray lock file is
// left behind and a killed process releases it with its descriptors. On Linux
// flock locks are independent of the POSIX (fcntl) locks SQLite uses.
//
// The descriptor is never closed: closing any descriptor of a file drops
// every POSIX lock this process holds on it, SQLite's included. Each file
// keeps one descriptor for the life of the process and is unlocked (not
// closed) when its last DatabaseWriterLock goes away.
#include "colmap_bridge/database_writer_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <map>
#include <mutex>
#include <utility>

#include "colmap_bridge/database.h"

namespace cashash {
namespace colmap {
namespace {

struct HeldFile {
  int fd = -1;
  int holders = 0;
};

std::mutex& Mutex() {
  static std::mutex mutex;
  return mutex;
}

// Keyed by (device, inode): one entry per file whatever path names it.
std::map<std::pair<dev_t, ino_t>, HeldFile>& Files() {
  static auto* files = new std::map<std::pair<dev_t, ino_t>, HeldFile>();
  return *files;
}

HeldFile* FindByDescriptor(int fd) {
  for (auto& entry : Files()) {
    if (entry.second.fd == fd) return &entry.second;
  }
  return nullptr;
}

}  // namespace

DatabaseWriterLock::DatabaseWriterLock(const std::string& database_path) {
  struct stat info;
  if (stat(database_path.c_str(), &info) != 0) {
    throw DatabaseError("cannot lock database " + database_path + ": " + std::strerror(errno));
  }
  std::lock_guard<std::mutex> lock(Mutex());
  HeldFile& held = Files()[{info.st_dev, info.st_ino}];
  if (held.holders > 0) {
    ++held.holders;
    fd_ = held.fd;
    return;
  }
  if (held.fd < 0) {
    held.fd = open(database_path.c_str(), O_RDONLY | O_CLOEXEC);
    if (held.fd < 0) {
      throw DatabaseError("cannot lock database " + database_path + ": " + std::strerror(errno));
    }
  }
  if (flock(held.fd, LOCK_EX | LOCK_NB) != 0) {
    if (errno == EWOULDBLOCK) {
      throw DatabaseError("database " + database_path +
                          " is being matched by another cashash process; wait for it to finish "
                          "(or stop it, then run again to resume)");
    }
    throw DatabaseError("cannot lock database " + database_path + ": " + std::strerror(errno));
  }
  held.holders = 1;
  fd_ = held.fd;
}

DatabaseWriterLock::~DatabaseWriterLock() {
  std::lock_guard<std::mutex> lock(Mutex());
  HeldFile* held = FindByDescriptor(fd_);
  if (held == nullptr || --held->holders > 0) return;
  flock(held->fd, LOCK_UN);
}

}  // namespace colmap
}  // namespace cashash
