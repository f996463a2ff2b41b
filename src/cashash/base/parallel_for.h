// ParallelFor: runs fn(i) for i in [0, n) on up to num_threads threads
// (-1 or 0 = every core), started for the call and joined before it
// returns (no pool: callers on several threads at once never wait for each
// other's work). Work is handed out one index at a time, so uneven items
// (image pairs of different sizes) balance themselves. The first exception
// thrown by fn stops the remaining work and is rethrown here.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace cashash {

inline int ResolveNumThreads(int num_threads) {
  if (num_threads > 0) return num_threads;
  const unsigned cores = std::thread::hardware_concurrency();
  return cores == 0 ? 1 : static_cast<int>(cores);
}

// fn(i, worker): worker in [0, number of threads used) identifies the calling
// thread, so callers can keep per-thread scratch memory.
template <typename Fn>
void ParallelForWorkers(size_t n, int num_threads, Fn&& fn) {
  const size_t num_workers = std::min<size_t>(n, static_cast<size_t>(ResolveNumThreads(num_threads)));
  if (num_workers <= 1) {
    for (size_t i = 0; i < n; ++i) fn(i, size_t{0});
    return;
  }
  std::atomic<size_t> next{0};
  std::exception_ptr first_error;
  std::mutex error_mutex;
  auto work = [&](size_t worker) {
    for (size_t i = next.fetch_add(1); i < n; i = next.fetch_add(1)) {
      try {
        fn(i, worker);
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!first_error) first_error = std::current_exception();
        next.store(n);
      }
    }
  };
  std::vector<std::thread> threads;
  threads.reserve(num_workers - 1);
  for (size_t w = 1; w < num_workers; ++w) threads.emplace_back(work, w);
  work(0);
  for (std::thread& thread : threads) thread.join();
  if (first_error) std::rethrow_exception(first_error);
}

template <typename Fn>
void ParallelFor(size_t n, int num_threads, Fn&& fn) {
  ParallelForWorkers(n, num_threads, [&fn](size_t i, size_t) { fn(i); });
}

// Number of workers ParallelForWorkers(n, num_threads, ...) will use.
inline size_t NumParallelWorkers(size_t n, int num_threads) {
  return std::max<size_t>(1, std::min<size_t>(n, static_cast<size_t>(ResolveNumThreads(num_threads))));
}

}  // namespace cashash
