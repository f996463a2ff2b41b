// A bounded multi-producer multi-consumer queue used between the pipeline's
// stages (matching -> verification -> writing), so that a slow stage applies
// back-pressure instead of letting results pile up in memory.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <mutex>
#include <optional>

namespace cashash {

template <typename T>
class BlockingQueue {
 public:
  explicit BlockingQueue(size_t capacity) : capacity_(capacity == 0 ? 1 : capacity) {}

  // Blocks while full. Returns false if the queue was closed.
  bool Push(T item) {
    std::unique_lock<std::mutex> lock(mutex_);
    not_full_.wait(lock, [&] { return closed_ || items_.size() < capacity_; });
    if (closed_) return false;
    items_.push_back(std::move(item));
    // All: consumers may wait for different things (PopWhenBacklogged).
    not_empty_.notify_all();
    return true;
  }

  // Blocks while empty; returns nullopt once closed and drained.
  std::optional<T> Pop() { return PopWhenBacklogged(1); }

  // As Pop, but waits until at least `backlog` items wait or the queue is
  // closed: for a helper consumer that should work only when the others
  // cannot keep up (the producer is about to block) or at the end.
  std::optional<T> PopWhenBacklogged(size_t backlog) {
    std::unique_lock<std::mutex> lock(mutex_);
    not_empty_.wait(lock, [&] { return closed_ || (!items_.empty() && items_.size() >= backlog); });
    if (items_.empty()) return std::nullopt;
    T item = std::move(items_.front());
    items_.pop_front();
    not_full_.notify_one();
    return item;
  }

  size_t capacity() const { return capacity_; }

  // No more pushes; consumers drain what is left.
  void Close() {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
    not_empty_.notify_all();
    not_full_.notify_all();
  }

 private:
  const size_t capacity_;
  std::mutex mutex_;
  std::condition_variable not_empty_;
  std::condition_variable not_full_;
  std::deque<T> items_;
  bool closed_ = false;
};

}  // namespace cashash
