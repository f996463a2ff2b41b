// The queue between the pipeline's stages: order, back-pressure, closing,
// the helper consumer's pop that waits for a backlog, and the batch pop
// whose extra items keep their room until released.
#include <gtest/gtest.h>

#include <chrono>
#include <future>
#include <optional>
#include <thread>
#include <vector>

#include "cashash/pipeline/blocking_queue.h"

namespace cashash {
namespace {

using namespace std::chrono_literals;

TEST(BlockingQueue, FirstInFirstOutAndDrainedAfterClose) {
  BlockingQueue<int> queue(3);
  EXPECT_TRUE(queue.Push(1));
  EXPECT_TRUE(queue.Push(2));
  queue.Close();
  EXPECT_FALSE(queue.Push(3));
  EXPECT_EQ(queue.Pop(), std::optional<int>(1));
  EXPECT_EQ(queue.Pop(), std::optional<int>(2));
  EXPECT_EQ(queue.Pop(), std::nullopt);
}

TEST(BlockingQueue, HelperPopWaitsForTheBacklog) {
  BlockingQueue<int> queue(2);
  ASSERT_EQ(queue.capacity(), 2u);
  queue.Push(1);
  std::future<std::optional<int>> helper =
      std::async(std::launch::async, [&] { return queue.PopWhenBacklogged(queue.capacity()); });
  // One item waits: the helper leaves it to the first consumer.
  EXPECT_EQ(helper.wait_for(100ms), std::future_status::timeout);
  queue.Push(2);  // the queue is full: the producer would block next
  EXPECT_EQ(helper.get(), std::optional<int>(1));
  EXPECT_EQ(queue.Pop(), std::optional<int>(2));
}

TEST(BlockingQueue, HelperPopTakesWhatIsLeftOnceClosed) {
  BlockingQueue<int> queue(4);
  queue.Push(7);
  std::future<std::optional<int>> helper =
      std::async(std::launch::async, [&] { return queue.PopWhenBacklogged(queue.capacity()); });
  EXPECT_EQ(helper.wait_for(100ms), std::future_status::timeout);
  queue.Close();
  EXPECT_EQ(helper.get(), std::optional<int>(7));
  EXPECT_EQ(queue.PopWhenBacklogged(4), std::nullopt);
}

// A plain consumer is woken by a push even while a helper waits beside it
// (a push wakes every waiting consumer, not one that might go back to sleep).
TEST(BlockingQueue, APushReachesThePlainConsumerWhileAHelperWaits) {
  BlockingQueue<int> queue(8);
  std::future<std::optional<int>> helper =
      std::async(std::launch::async, [&] { return queue.PopWhenBacklogged(queue.capacity()); });
  std::future<std::optional<int>> plain = std::async(std::launch::async, [&] { return queue.Pop(); });
  std::this_thread::sleep_for(50ms);  // both waiting
  queue.Push(5);
  ASSERT_EQ(plain.wait_for(10s), std::future_status::ready);
  EXPECT_EQ(plain.get(), std::optional<int>(5));
  queue.Close();
  EXPECT_EQ(helper.get(), std::nullopt);
}

TEST(BlockingQueue, ABatchTakesWhatWaitsInOrderUpToItsSize) {
  BlockingQueue<int> queue(8);
  for (int k = 1; k <= 5; ++k) queue.Push(k);
  EXPECT_EQ(queue.PopBatch(1, 3), (std::vector<int>{1, 2, 3}));
  queue.Release(2);
  EXPECT_EQ(queue.PopBatch(1, 3), (std::vector<int>{4, 5}));  // what waits, not more
  queue.Release(1);
  queue.Push(6);
  EXPECT_EQ(queue.PopBatch(1, 0), (std::vector<int>{6}));  // at least one
  queue.Close();
  EXPECT_TRUE(queue.PopBatch(1, 3).empty());
}

// The items of a batch beyond its first stay counted against the capacity
// until released: the producer cannot run further ahead than with one pop.
TEST(BlockingQueue, ABatchKeepsTheRoomOfItsExtraItemsUntilReleased) {
  BlockingQueue<int> queue(3);
  for (int k = 1; k <= 3; ++k) queue.Push(k);
  ASSERT_EQ(queue.PopBatch(1, 3).size(), 3u);  // the first frees its room
  EXPECT_TRUE(queue.Push(4));
  std::future<bool> producer = std::async(std::launch::async, [&] { return queue.Push(5); });
  EXPECT_EQ(producer.wait_for(100ms), std::future_status::timeout);
  queue.Release(2);
  ASSERT_EQ(producer.wait_for(10s), std::future_status::ready);
  EXPECT_TRUE(producer.get());
  EXPECT_EQ(queue.PopBatch(1, 8), (std::vector<int>{4, 5}));
}

// The helper's backlog counts the held items too: it starts once the
// producer would block, queued or held.
TEST(BlockingQueue, TheHelpersBacklogCountsHeldItems) {
  BlockingQueue<int> queue(3);
  for (int k = 1; k <= 3; ++k) queue.Push(k);
  ASSERT_EQ(queue.PopBatch(1, 2).size(), 2u);  // 3 waits, 2 held
  std::future<std::optional<int>> helper =
      std::async(std::launch::async, [&] { return queue.PopWhenBacklogged(queue.capacity()); });
  EXPECT_EQ(helper.wait_for(100ms), std::future_status::timeout);  // 1 queued + 1 held
  queue.Push(4);  // full: the producer would block next
  ASSERT_EQ(helper.wait_for(10s), std::future_status::ready);
  EXPECT_EQ(helper.get(), std::optional<int>(3));
}

}  // namespace
}  // namespace cashash
