// What ranks > 0 send to rank 0: results survive encoding bit for bit, big
// chunks split into parts, damaged messages are refused; the round-robin
// split gives every chunk to exactly one rank.
#include "distributed/mpi_result_codec.h"

#include <set>
#include <stdexcept>

#include <gtest/gtest.h>

#include "cashash/pipeline/pair_chunk_source.h"
#include "cashash/pipeline/pair_generation.h"
#include "cashash/base/pair_id.h"
#include "distributed/mpi_distributed.h"
#include "distributed/mpi_world.h"

namespace cashash {
namespace distributed {
namespace {

PairResult MakeResult(image_t a, image_t b, size_t num_matches) {
  PairResult r;
  r.pair = ImagePair(a, b);
  for (point2D_t k = 0; k < num_matches; ++k) r.matches.push_back({k, 3 * k + 1});
  r.geometry.config = kCalibrated;
  r.geometry.F << 1, 2, 3, 4, 5, 6, 7, 8, 9.5;
  r.geometry.E = r.geometry.F * -0.25;
  r.geometry.H = r.geometry.F.transpose();
  r.geometry.qvec << 0.5, 0.5, -0.5, 0.5;
  r.geometry.tvec << 1e-300, -3.0, 7.25;
  r.geometry.inlier_matches.assign(r.matches.begin(), r.matches.begin() + num_matches / 2);
  return r;
}

void ExpectSame(const PairResult& a, const PairResult& b) {
  EXPECT_EQ(a.pair, b.pair);
  EXPECT_EQ(a.matches, b.matches);
  EXPECT_EQ(a.geometry.config, b.geometry.config);
  EXPECT_EQ(a.geometry.F, b.geometry.F);
  EXPECT_EQ(a.geometry.E, b.geometry.E);
  EXPECT_EQ(a.geometry.H, b.geometry.H);
  EXPECT_EQ(a.geometry.qvec, b.geometry.qvec);
  EXPECT_EQ(a.geometry.tvec, b.geometry.tvec);
  EXPECT_EQ(a.geometry.inlier_matches, b.geometry.inlier_matches);
}

TEST(MpiResultCodec, ChunkRoundTrips) {
  ChunkResultsMessage message;
  message.block_i = 2;
  message.block_j = 7;
  message.num_blocks = 9;
  message.last_part = false;
  message.results = {MakeResult(1, 2, 10), MakeResult(5, 3, 0), MakeResult(70000, 12, 1000)};
  const ChunkResultsMessage back = DecodeChunkResults(EncodeChunkResults(message));
  EXPECT_EQ(back.block_i, 2);
  EXPECT_EQ(back.block_j, 7);
  EXPECT_EQ(back.num_blocks, 9);
  EXPECT_FALSE(back.last_part);
  ASSERT_EQ(back.results.size(), 3u);
  for (size_t k = 0; k < 3; ++k) ExpectSame(back.results[k], message.results[k]);
}

TEST(MpiResultCodec, LargeChunksSplitIntoOrderedParts) {
  std::vector<PairResult> results;
  for (image_t k = 1; k <= 50; ++k) results.push_back(MakeResult(k, k + 100, 200));
  PairChunk chunk;
  chunk.block_i = 1;
  chunk.block_j = 3;
  chunk.num_blocks = 4;
  const auto parts = EncodeChunkInParts(chunk, results, 8000);  // about 4 results per part
  ASSERT_GT(parts.size(), 5u);
  std::vector<PairResult> joined;
  for (size_t p = 0; p < parts.size(); ++p) {
    EXPECT_LE(parts[p].size(), 8000u + 64u);
    ChunkResultsMessage m = DecodeChunkResults(parts[p]);
    EXPECT_EQ(m.last_part, p + 1 == parts.size());
    EXPECT_EQ(m.block_j, 3);
    for (PairResult& r : m.results) joined.push_back(std::move(r));
  }
  ASSERT_EQ(joined.size(), results.size());
  for (size_t k = 0; k < results.size(); ++k) ExpectSame(joined[k], results[k]);
  // An empty chunk is still one (last) message.
  const auto empty = EncodeChunkInParts(chunk, {}, 8000);
  ASSERT_EQ(empty.size(), 1u);
  EXPECT_TRUE(DecodeChunkResults(empty[0]).last_part);
}

TEST(MpiResultCodec, DamagedMessagesAreRefused) {
  ChunkResultsMessage message;
  message.results = {MakeResult(1, 2, 10)};
  std::vector<uint8_t> bytes = EncodeChunkResults(message);
  std::vector<uint8_t> truncated(bytes.begin(), bytes.end() - 5);
  EXPECT_THROW(DecodeChunkResults(truncated), std::runtime_error);
  bytes.push_back(0);
  EXPECT_THROW(DecodeChunkResults(bytes), std::runtime_error);
  EXPECT_THROW(DecodeChunkResults({}), std::runtime_error);
}

TEST(MpiResultCodec, RankReportRoundTrips) {
  RankReport report;
  report.stats.pairs_total = 100;
  report.stats.pairs_done = 99;
  report.stats.raw_matches = 123456;
  report.stats.verified_pairs = 90;
  report.stats.inlier_matches = 65432;
  report.stats.verification_calls = 7;
  report.stats.seconds_total = 12.5;
  report.stats.seconds_verification = 3.25;
  report.stats.stopped = true;
  report.matcher_name = "gpu-cascade";
  const RankReport back = DecodeRankReport(EncodeRankReport(report));
  EXPECT_EQ(back.stats.pairs_done, 99u);
  EXPECT_EQ(back.stats.inlier_matches, 65432u);
  EXPECT_EQ(back.stats.verification_calls, 7u);
  EXPECT_EQ(back.stats.seconds_total, 12.5);
  EXPECT_EQ(back.stats.seconds_verification, 3.25);
  EXPECT_TRUE(back.stats.stopped);
  EXPECT_EQ(back.matcher_name, "gpu-cascade");
}

TEST(MpiDistributed, RoundRobinGivesEveryChunkToOneRank) {
  std::vector<image_t> ids;
  for (image_t i = 1; i <= 23; ++i) ids.push_back(i);
  const std::vector<PairChunk> reference = ScheduledPairChunks(ids, 4, 2);
  const ScheduledChunkSource chunks(ids, 4, 2);
  for (int size : {1, 2, 3, 7, 100}) {
    std::set<pair_t> seen;
    size_t num_chunks = 0, num_pairs = 0;
    for (int rank = 0; rank < size; ++rank) {
      const ChunksOfRank mine(&chunks, rank, size);
      num_chunks += mine.size();
      num_pairs += mine.num_pairs();
      for (size_t k = 0; k < mine.size(); ++k) {
        // Chunk k of a rank is chunk rank + k * size of the run, as before.
        const PairChunk chunk = mine.Chunk(k);
        EXPECT_EQ(chunk.pairs, reference[rank + k * size].pairs);
        EXPECT_EQ(mine.NumPairs(k), chunk.pairs.size());
        for (const ImagePair& p : chunk.pairs) EXPECT_TRUE(seen.insert(ImagePairToPairId(p.first, p.second)).second);
      }
    }
    EXPECT_EQ(seen.size(), 23u * 22u / 2u) << "size " << size;
    EXPECT_EQ(num_chunks, reference.size());
    EXPECT_EQ(num_pairs, 23u * 22u / 2u);
  }
  EXPECT_EQ(chunks.Checksum(), ScheduledChunkSource(ids, 4, 2).Checksum());
  EXPECT_NE(chunks.Checksum(), ScheduledChunkSource(ids, 4, 3).Checksum());
  EXPECT_NE(chunks.Checksum(), ScheduledChunkSource(ids, 5, 2).Checksum());
  std::vector<image_t> other = ids;
  other.back() += 1;
  EXPECT_NE(chunks.Checksum(), ScheduledChunkSource(other, 4, 2).Checksum());
  // Ranks that resumed from different completed pairs disagree.
  PairTriangle done_a(ids.size()), done_b(ids.size());
  done_a.Set(0, 1);
  done_b.Set(0, 2);
  EXPECT_NE(ScheduledChunkSource(ids, 4, 2, done_a).Checksum(), ScheduledChunkSource(ids, 4, 2, done_b).Checksum());
  EXPECT_NE(ScheduledChunkSource(ids, 4, 2, done_a).Checksum(), chunks.Checksum());
  // A pair list's chunks: over their pairs.
  const ChunkList listed(&reference);
  EXPECT_EQ(listed.Checksum(), ChunkList(&reference).Checksum());
  const std::vector<PairChunk> fewer(reference.begin(), reference.end() - 1);
  EXPECT_NE(listed.Checksum(), ChunkList(&fewer).Checksum());
}

TEST(MpiWorld, WithoutALauncherIsAWorldOfOne) {
  if (MpiSize() > 1) GTEST_SKIP() << "run under mpirun";
  EXPECT_EQ(MpiRank(), 0);
  EXPECT_EQ(MpiMin(42), 42u);
  EXPECT_EQ(MpiMax(42), 42u);
  MpiBarrier();
}

}  // namespace
}  // namespace distributed
}  // namespace cashash
