// PhaseClock: each mark ends one phase, repeated names add up, and the
// phases together are the time since the clock was made.
#include "cashash/base/phase_clock.h"

#include <chrono>
#include <thread>

#include <gtest/gtest.h>

namespace cashash {
namespace {

TEST(PhaseClock, EachMarkEndsThePhaseUnderWay) {
  PhaseClock clock;
  const auto start = std::chrono::steady_clock::now();
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  clock.Mark("first");
  clock.Mark("second");  // nothing happened in between
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_EQ(clock.phases().size(), 2u);
  EXPECT_EQ(clock.phases()[0].name, "first");
  EXPECT_GE(clock.phases()[0].seconds, 0.02);
  EXPECT_EQ(clock.phases()[1].name, "second");
  EXPECT_LT(clock.phases()[1].seconds, clock.phases()[0].seconds);
  EXPECT_LE(clock.TotalSeconds(), elapsed + 1e-3);
}

TEST(PhaseClock, ANameGivenAgainAddsToItsPhase) {
  PhaseClock clock;
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  clock.Mark("waiting");
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  clock.Mark("working");
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  clock.Mark("waiting");
  ASSERT_EQ(clock.phases().size(), 2u);
  EXPECT_EQ(clock.phases()[0].name, "waiting");
  EXPECT_GE(clock.phases()[0].seconds, 0.02);
  EXPECT_EQ(clock.phases()[1].name, "working");
  EXPECT_NEAR(clock.TotalSeconds(), clock.phases()[0].seconds + clock.phases()[1].seconds, 1e-12);
}

}  // namespace
}  // namespace cashash
