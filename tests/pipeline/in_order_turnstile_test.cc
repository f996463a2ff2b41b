// Tickets pass in order whatever order their threads arrive in, and a
// cancel releases every waiter.
#include "cashash/pipeline/in_order_turnstile.h"

#include <gtest/gtest.h>

#include <chrono>
#include <mutex>
#include <thread>
#include <vector>

namespace cashash {
namespace {

TEST(InOrderTurnstile, TicketsPassInOrderWhateverOrderTheyArriveIn) {
  InOrderTurnstile turnstile;
  std::mutex mutex;
  std::vector<size_t> passed;
  std::vector<std::thread> threads;
  // The last ticket arrives first, the first one last.
  for (size_t ticket = 5; ticket-- > 0;) {
    threads.emplace_back([&, ticket] {
      ASSERT_TRUE(turnstile.Wait(ticket));
      {
        std::lock_guard<std::mutex> lock(mutex);
        passed.push_back(ticket);
      }
      turnstile.Pass(ticket);
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(passed, (std::vector<size_t>{0, 1, 2, 3, 4}));
}

TEST(InOrderTurnstile, CancelReleasesWaitersWithFalse) {
  InOrderTurnstile turnstile;
  bool result = true;
  std::thread waiter([&] { result = turnstile.Wait(3); });
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  turnstile.Cancel();
  waiter.join();
  EXPECT_FALSE(result);
  EXPECT_FALSE(turnstile.Wait(0));  // later callers too
}

}  // namespace
}  // namespace cashash
