// One cashash writer per database file at a time. Two matchers writing the
// same database would each match every pair and overwrite each other's rows;
// the second one is refused at once instead, with a message saying why.
#pragma once

#include <string>

namespace cashash {
namespace colmap {

class DatabaseWriterLock {
 public:
  // Throws DatabaseError when another process holds the lock on the file.
  // Locks taken by this process on the same file nest.
  explicit DatabaseWriterLock(const std::string& database_path);
  ~DatabaseWriterLock();
  DatabaseWriterLock(const DatabaseWriterLock&) = delete;
  DatabaseWriterLock& operator=(const DatabaseWriterLock&) = delete;

 private:
  int fd_ = -1;
};

}  // namespace colmap
}  // namespace cashash
