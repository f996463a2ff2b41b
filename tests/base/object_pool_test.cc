// ObjectPool: objects are made on first need, reused once given back, never
// held by two callers at once, and not reused when not given back.
#include "cashash/base/object_pool.h"

#include <atomic>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace cashash {
namespace {

TEST(ObjectPool, MakesOnFirstNeedAndReusesWhatIsGivenBack) {
  int next_id = 0;
  ObjectPool<int> pool([&]() { return std::make_unique<int>(next_id++); });
  EXPECT_EQ(pool.made(), 0u);
  std::unique_ptr<int> a = pool.Acquire();
  std::unique_ptr<int> b = pool.Acquire();
  EXPECT_NE(*a, *b);
  EXPECT_EQ(pool.made(), 2u);
  int* given_back = a.get();
  pool.Release(std::move(a));
  std::unique_ptr<int> c = pool.Acquire();
  EXPECT_EQ(c.get(), given_back);
  EXPECT_EQ(pool.made(), 2u);
  // Not given back (a failed user): the next caller gets a new one.
  b.reset();
  c.reset();
  pool.Acquire();
  EXPECT_EQ(pool.made(), 3u);
  EXPECT_THROW(ObjectPool<int>(nullptr), std::invalid_argument);
}

TEST(ObjectPool, NoObjectIsHeldByTwoThreadsAtOnce) {
  struct Counter {
    std::atomic<int> users{0};
  };
  ObjectPool<Counter> pool([]() { return std::make_unique<Counter>(); });
  std::atomic<int> overlaps{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&]() {
      for (int k = 0; k < 2000; ++k) {
        std::unique_ptr<Counter> object = pool.Acquire();
        if (++object->users != 1) ++overlaps;
        --object->users;
        pool.Release(std::move(object));
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(overlaps.load(), 0);
  EXPECT_GE(pool.made(), 1u);
  EXPECT_LE(pool.made(), 4u);
}

}  // namespace
}  // namespace cashash
