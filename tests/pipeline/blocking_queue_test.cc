// The queue between the pipeline's stages: order, back-pressure, closing,
// and the helper consumer's pop that waits for a backlog.
#include <gtest/gtest.h>

#include <chrono>
#include <future>
#include <optional>
#include <thread>

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

}  // namespace
}  // namespace cashash
