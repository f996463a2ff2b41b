// Objects that are costly to make and used by one thread at a time (a
// brute-force matcher for deferred rematches, a SQLite connection for
// loading features): made on first need, handed back, reused. Thread-safe.
#pragma once

#include <cstddef>
#include <functional>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <utility>
#include <vector>

namespace cashash {

template <typename T>
class ObjectPool {
 public:
  explicit ObjectPool(std::function<std::unique_ptr<T>()> make) : make_(std::move(make)) {
    if (!make_) throw std::invalid_argument("ObjectPool needs a way to make its objects");
  }

  // An object no other caller holds; give it back with Release. One that
  // is not given back (its user failed half-way) is simply not reused.
  std::unique_ptr<T> Acquire() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!idle_.empty()) {
        std::unique_ptr<T> object = std::move(idle_.back());
        idle_.pop_back();
        return object;
      }
    }
    // Made outside the lock: a GPU matcher takes a while to set up.
    std::unique_ptr<T> object = make_();
    std::lock_guard<std::mutex> lock(mutex_);
    ++made_;
    return object;
  }

  void Release(std::unique_ptr<T> object) {
    std::lock_guard<std::mutex> lock(mutex_);
    idle_.push_back(std::move(object));
  }

  // Objects made so far.
  size_t made() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return made_;
  }

 private:
  std::function<std::unique_ptr<T>()> make_;
  mutable std::mutex mutex_;
  std::vector<std::unique_ptr<T>> idle_;
  size_t made_ = 0;
};

}  // namespace cashash
