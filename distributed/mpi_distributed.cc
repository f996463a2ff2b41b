#include "distributed/mpi_distributed.h"

#include <algorithm>
#include <exception>
#include <map>

#include "distributed/mpi_world.h"

namespace cashash {
namespace distributed {
namespace {

constexpr size_t kMaxMessageBytes = size_t{256} << 20;

}  // namespace

ChunksOfRank::ChunksOfRank(const PairChunkSource* chunks, int rank, int size)
    : chunks_(chunks), rank_(static_cast<size_t>(rank)), step_(static_cast<size_t>(std::max(1, size))) {
  if (rank_ < chunks_->size()) size_ = (chunks_->size() - rank_ + step_ - 1) / step_;
  for (size_t k = 0; k < size_; ++k) num_pairs_ += chunks_->NumPairs(Of(k));
}

uint64_t ChunksOfRank::Checksum() const {
  uint64_t hash = chunks_->Checksum();
  for (uint64_t value : {static_cast<uint64_t>(rank_), static_cast<uint64_t>(step_)}) {
    hash ^= value + 0x9e3779b97f4a7c15ull + (hash << 6) + (hash >> 2);
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


MpiResultSender::MpiResultSender(const PairChunkSource* chunks) : chunks_(chunks) {}

void MpiResultSender::WriteChunk(const std::vector<PairResult>& results) {
  if (results.empty()) return;
  PairChunk header;
  if (next_chunk_ < chunks_->size()) {
    const PairChunk chunk = chunks_->Outline(next_chunk_++);
    header.block_i = chunk.block_i;
    header.block_j = chunk.block_j;
    header.num_blocks = chunk.num_blocks;
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
