// Matching split across MPI ranks: each rank matches and verifies every
// R-th chunk (round-robin, so a block pair's cost does not pile up on one
// rank); ranks > 0 send their results to rank 0, the only process that
// writes the database. Rank 0 writes its own chunks from its pipeline's
// writer thread and the others' from a receiving thread, one transaction
// per chunk either way, through one locked sink.
#pragma once

#include <atomic>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "cashash/pipeline/matching_pipeline.h"
#include "cashash/pipeline/pair_chunk_source.h"
#include "cashash/base/pair_id.h"
#include "distributed/mpi_result_codec.h"

namespace cashash {
namespace distributed {

// This rank's share of the run's chunks: chunks k of `chunks` with
// k % size == rank, made when asked for. Ranks check that they agree on
// the run's chunks by comparing chunks.Checksum().
class ChunksOfRank : public PairChunkSource {
 public:
  // `chunks` must outlive this share.
  ChunksOfRank(const PairChunkSource* chunks, int rank, int size);
  size_t size() const override { return size_; }
  size_t num_pairs() const override { return num_pairs_; }
  size_t NumPairs(size_t k) const override { return chunks_->NumPairs(Of(k)); }
  PairChunk Chunk(size_t k) const override { return chunks_->Chunk(Of(k)); }
  PairChunk Outline(size_t k) const override { return chunks_->Outline(Of(k)); }
  uint64_t Checksum() const override;

 private:
  size_t Of(size_t k) const { return rank_ + k * step_; }

  const PairChunkSource* chunks_;
  size_t rank_, step_, size_ = 0, num_pairs_ = 0;
};

// Serialises WriteChunk calls from several threads onto one sink and counts
// the pairs written.
class LockedSink : public ResultSink {
 public:
  explicit LockedSink(ResultSink* sink) : sink_(sink) {}
  void WriteChunk(const std::vector<PairResult>& results) override;
  void Flush() override;
  size_t pairs_written() const { return pairs_written_; }

 private:
  ResultSink* sink_;
  std::mutex mutex_;
  std::atomic<size_t> pairs_written_{0};
};

// The sink of ranks > 0: each chunk goes to rank 0 (in parts of at most
// 256 MiB). `chunks` are this rank's chunks (not owned), to name them in
// the messages: the pipeline writes them in their order, so the k-th call
// of WriteChunk is chunk k.
class MpiResultSender : public ResultSink {
 public:
  explicit MpiResultSender(const PairChunkSource* chunks);
  void WriteChunk(const std::vector<PairResult>& results) override;
  // Sent once, after the pipeline has finished.
  static void SendReport(const RankReport& report);

 private:
  const PairChunkSource* chunks_;
  size_t next_chunk_ = 0;
};

// Rank 0's receiving thread: writes every chunk the other ranks send into
// `sink` and calls on_chunk after each; stops once every rank has reported.
// Errors end the whole job (MpiAbortJob): the others could not be told.
class MpiResultReceiver {
 public:
  using ChunkCallback = std::function<void(const PairChunk& chunk)>;
  MpiResultReceiver(ResultSink* sink, ChunkCallback on_chunk);
  ~MpiResultReceiver();
  // Waits for every rank's report.
  std::vector<RankReport> Join();

 private:
  void Loop();

  ResultSink* sink_;
  ChunkCallback on_chunk_;
  std::vector<RankReport> reports_;
  std::thread thread_;
};

constexpr int kMpiTagChunk = 1;
constexpr int kMpiTagReport = 2;

}  // namespace distributed
}  // namespace cashash
