// A bounded multi-producer multi-consumer queue used between the pipeline's
// stages (matching -> verification -> writing), so that a slow stage applies
// back-pressure instead of letting results pile up in memory.
#pragma once

#include <algorithm>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <mutex>
#include <optional>
#include <vector>

namespace cashash {

template <typename T>
class BlockingQueue {
 public:
  explicit BlockingQueue(size_t capacity) : capacity_(capacity == 0 ? 1 : capacity) {}

  // Blocks while full. Returns false if the queue was closed.
  bool Push(T item) {
    std::unique_lock<std::mutex> lock(mutex_);
    not_full_.wait(lock, [&] { return closed_ || items_.size() + held_ < capacity_; });
    if (closed_) return false;
    items_.push_back(std::move(item));
    // All: consumers may wait for different things (PopWhenBacklogged).
    not_empty_.notify_all();
    return true;
  }

  // Blocks while empty; returns nullopt once closed and drained.
  std::optional<T> Pop() { return PopWhenBacklogged(1); }

  // As Pop, but gives up after `timeout`: then returns nullopt with
  // *timed_out set (false when it returns an item or the queue is closed
  // and drained).
  template <typename Duration>
  std::optional<T> PopWithin(Duration timeout, bool* timed_out) {
    std::unique_lock<std::mutex> lock(mutex_);
    *timed_out = !not_empty_.wait_for(lock, timeout, [&] { return closed_ || !items_.empty(); });
    if (items_.empty()) return std::nullopt;
    T item = std::move(items_.front());
    items_.pop_front();
    not_full_.notify_one();
    return item;
  }

  // As Pop, but waits until at least `backlog` items wait or the queue is
  // closed: for a helper consumer that should work only when the others
  // cannot keep up (the producer is about to block) or at the end.
  std::optional<T> PopWhenBacklogged(size_t backlog) {
    std::unique_lock<std::mutex> lock(mutex_);
    WaitForBacklog(lock, backlog);
    if (items_.empty()) return std::nullopt;
    T item = std::move(items_.front());
    items_.pop_front();
    not_full_.notify_one();
    return item;
  }

  // As PopWhenBacklogged, then also takes what else waits, up to max_items
  // in all, in order; empty once closed and drained. All but the first stay
  // counted against the capacity until Release(size() - 1): what a consumer
  // holds in one batch is bounded as if it still waited, so the memory the
  // queue's capacity stands for (kPipelineBlocks) does not grow with it.
  std::vector<T> PopBatch(size_t backlog, size_t max_items) {
    std::unique_lock<std::mutex> lock(mutex_);
    WaitForBacklog(lock, backlog);
    std::vector<T> batch;
    const size_t n = std::min(items_.size(), std::max<size_t>(1, max_items));
    for (size_t k = 0; k < n; ++k) {
      batch.push_back(std::move(items_.front()));
      items_.pop_front();
    }
    if (n > 0) {
      held_ += n - 1;
      not_full_.notify_one();
    }
    return batch;
  }

  // Gives back the room of `held` items a PopBatch kept counted.
  void Release(size_t held) {
    if (held == 0) return;
    std::lock_guard<std::mutex> lock(mutex_);
    held_ -= std::min(held, held_);
    not_full_.notify_all();
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
  // Until closed: `backlog` items count as waiting (queued or held in a
  // batch, so that the producer is about to block) and one is queued.
  void WaitForBacklog(std::unique_lock<std::mutex>& lock, size_t backlog) {
    not_empty_.wait(lock, [&] { return closed_ || (!items_.empty() && items_.size() + held_ >= backlog); });
  }

  const size_t capacity_;
  std::mutex mutex_;
  std::condition_variable not_empty_;
  std::condition_variable not_full_;
  std::deque<T> items_;
  size_t held_ = 0;  // items of batches still counted (PopBatch)
  bool closed_ = false;
};

}  // namespace cashash
