// The streams' priorities by role: matching first, verification last, and
// the deferred exact rematch with matching unless asked below verification
// (CASHASH_REMATCH_PRIORITY=low). A pure mapping: no device needed.
#include <gtest/gtest.h>

#include "cashash_cuda/utils/stream_priority.cuh"

namespace cashash {
namespace {

using cuda::StagePriority;
using cuda::StreamRole;

TEST(StreamPriority, DefaultRematchRunsWithMatchingAndVerificationLast) {
  // An H100's range: 0 (least) to -5 (greatest); smaller is scheduled first.
  EXPECT_EQ(StagePriority(StreamRole::kMatching, 0, -5, false), -5);
  EXPECT_EQ(StagePriority(StreamRole::kDeferredRematch, 0, -5, false), -5);
  EXPECT_EQ(StagePriority(StreamRole::kVerification, 0, -5, false), 0);
}

TEST(StreamPriority, LowRematchGoesBelowVerification) {
  EXPECT_EQ(StagePriority(StreamRole::kMatching, 0, -5, true), -5);
  EXPECT_EQ(StagePriority(StreamRole::kVerification, 0, -5, true), -1);
  EXPECT_EQ(StagePriority(StreamRole::kDeferredRematch, 0, -5, true), 0);
  // Two levels: verification joins matching rather than leave the range.
  EXPECT_EQ(StagePriority(StreamRole::kVerification, 0, -1, true), -1);
  EXPECT_EQ(StagePriority(StreamRole::kDeferredRematch, 0, -1, true), 0);
  // One level: everything at it.
  EXPECT_EQ(StagePriority(StreamRole::kVerification, 0, 0, true), 0);
}

}  // namespace
}  // namespace cashash
