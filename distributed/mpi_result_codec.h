// Byte encoding of what ranks > 0 send to rank 0 under MPI: the results of
// a chunk of pairs (possibly in several parts) and, at the end, the rank's
// pipeline statistics. Plain bytes, no MPI here, so the format is tested
// without a launcher. Both ends run the same binary: native byte order.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "cashash/pipeline/matching_pipeline.h"

namespace cashash {
namespace distributed {

// One message of a chunk's results: where it comes from (for progress) and
// whether more parts of the same chunk follow.
struct ChunkResultsMessage {
  int block_i = 0;
  int block_j = 0;
  int num_blocks = 0;
  bool last_part = true;
  std::vector<PairResult> results;
};

std::vector<uint8_t> EncodeChunkResults(const ChunkResultsMessage& message);
// Throws std::runtime_error on a truncated or malformed message.
ChunkResultsMessage DecodeChunkResults(const std::vector<uint8_t>& bytes);

// Splits results into messages of at most max_bytes each (one result may
// exceed it alone), the last one flagged last_part.
std::vector<std::vector<uint8_t>> EncodeChunkInParts(const PairChunk& chunk, const std::vector<PairResult>& results,
                                                     size_t max_bytes);

struct RankReport {
  PipelineStats stats;
  std::string matcher_name;
};

std::vector<uint8_t> EncodeRankReport(const RankReport& report);
RankReport DecodeRankReport(const std::vector<uint8_t>& bytes);

}  // namespace distributed
}  // namespace cashash
