#include "distributed/mpi_distributed.h"

#include <exception>
#include <map>

#include "distributed/mpi_world.h"

namespace cashash {
namespace distributed {
namespace {

constexpr size_t kMaxMessageBytes = size_t{256} << 20;

}  // namespace

std::vector<PairChunk> ChunksOfRank(const std::vector<PairChunk>& chunks, int rank, int size) {
  std::vector<PairChunk> mine;
  for (size_t k = static_cast<size_t>(rank); k < chunks.size(); k += static_cast<size_t>(size)) {
    mine.push_back(chunks[k]);
  }
  return mine;
}

uint64_t ChunkListChecksum(const std::vector<PairChunk>& chunks) {
  uint64_t hash = 1469598103934665603ull;  // FNV-1a over the pair ids
  auto mix = [&hash](uint64_t value) {
    for (int byte = 0; byte < 8; ++byte) {
      hash ^= (value >> (8 * byte)) & 0xff;
      hash *= 1099511628211ull;
    }
  };
  for (const PairChunk& chunk : chunks) {
    mix(chunk.pairs.size());
    for (const ImagePair& pair : chunk.pairs) mix(ImagePairToPairId(pair.first, pair.second));
  }
  return hash;
}

void LockedSink::WriteChunk(const std::vector<PairResult>& results) {
  std::lock_guard<std::mutex> lock(mutex_);
  sink_->WriteChunk(results);
  pairs_written_ += results.size();
}

void LockedSink::Flush() {
  std::lock_guard<std::mutex> lock(mutex_);
  sink_->Flush();
}


MpiResultSender::MpiResultSender(const std::vector<PairChunk>& chunks) {
  for (const PairChunk& chunk : chunks) {
    if (!chunk.pairs.empty()) {
      chunk_of_first_pair_[ImagePairToPairId(chunk.pairs[0].first, chunk.pairs[0].second)] = &chunk;
    }
  }
}

void MpiResultSender::WriteChunk(const std::vector<PairResult>& results) {
  if (results.empty()) return;
  PairChunk header;
  const auto it = chunk_of_first_pair_.find(ImagePairToPairId(results[0].pair.first, results[0].pair.second));
  if (it != chunk_of_first_pair_.end()) {
    header.block_i = it->second->block_i;
    header.block_j = it->second->block_j;
    header.num_blocks = it->second->num_blocks;
  }
  for (const std::vector<uint8_t>& part : EncodeChunkInParts(header, results, kMaxMessageBytes)) {
    MpiSendBytes(part, 0, kMpiTagChunk);
  }
}

void MpiResultSender::SendReport(const RankReport& report) { MpiSendBytes(EncodeRankReport(report), 0, kMpiTagReport); }

MpiResultReceiver::MpiResultReceiver(ResultSink* sink, ChunkCallback on_chunk)
    : sink_(sink), on_chunk_(std::move(on_chunk)) {
  thread_ = std::thread([this]() { Loop(); });
}

MpiResultReceiver::~MpiResultReceiver() {
  if (thread_.joinable()) thread_.join();
}

std::vector<RankReport> MpiResultReceiver::Join() {
  if (thread_.joinable()) thread_.join();
  return reports_;
}

void MpiResultReceiver::Loop() {
  try {
    int reports_missing = MpiSize() - 1;
    // Parts of a chunk arrive in order from one rank (MPI keeps the order of
    // messages between two ranks); chunks of different ranks interleave.
    std::map<int, ChunkResultsMessage> partial;
    while (reports_missing > 0) {
      int source = 0, tag = 0;
      const std::vector<uint8_t> bytes = MpiReceiveAny(&source, &tag);
      if (tag == kMpiTagReport) {
        reports_.push_back(DecodeRankReport(bytes));
        --reports_missing;
        continue;
      }
      if (tag != kMpiTagChunk) throw std::runtime_error("unexpected MPI message tag " + std::to_string(tag));
      ChunkResultsMessage part = DecodeChunkResults(bytes);
      ChunkResultsMessage& chunk = partial[source];
      chunk.block_i = part.block_i;
      chunk.block_j = part.block_j;
      chunk.num_blocks = part.num_blocks;
      for (PairResult& r : part.results) chunk.results.push_back(std::move(r));
      if (!part.last_part) continue;
      sink_->WriteChunk(chunk.results);
      PairChunk done;
      done.block_i = chunk.block_i;
      done.block_j = chunk.block_j;
      done.num_blocks = chunk.num_blocks;
      for (const PairResult& r : chunk.results) done.pairs.push_back(r.pair);
      partial.erase(source);
      if (on_chunk_) on_chunk_(done);
    }
  } catch (const std::exception& e) {
    MpiAbortJob(std::string("receiving results from other ranks: ") + e.what());
  }
}

}  // namespace distributed
}  // namespace cashash
