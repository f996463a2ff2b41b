// Lets numbered tickets through one at a time, in ticket order. The
// pipeline verifies several chunks at once (a GPU chunk's time is set by
// its slowest pair, so one chunk at a time leaves the device idle), but the
// writer must still commit chunks in the order they were matched: progress,
// resume and the log read like COLMAP's block after block. A verification
// thread that finishes chunk k waits here until chunk k - 1 has been handed
// on; that wait also bounds how far the finished chunks can run ahead.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <mutex>

namespace cashash {

class InOrderTurnstile {
 public:
  // Blocks until every ticket below `ticket` has passed. False once
  // cancelled (an error elsewhere): the caller gives up its ticket.
  bool Wait(size_t ticket) {
    std::unique_lock<std::mutex> lock(mutex_);
    turn_.wait(lock, [&] { return cancelled_ || next_ == ticket; });
    return !cancelled_;
  }

  // `ticket` has been handed on; the next one may go.
  void Pass(size_t ticket) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (next_ == ticket) ++next_;
    turn_.notify_all();
  }

  // Releases every waiter with false, now and later.
  void Cancel() {
    std::lock_guard<std::mutex> lock(mutex_);
    cancelled_ = true;
    turn_.notify_all();
  }

 private:
  std::mutex mutex_;
  std::condition_variable turn_;
  size_t next_ = 0;
  bool cancelled_ = false;
};

}  // namespace cashash
