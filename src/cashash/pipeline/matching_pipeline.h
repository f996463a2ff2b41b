// The matching pipeline: load features of a chunk of pairs, match them with a
// FeatureMatcher backend (and, where the run asks for it, rematch the pairs
// that may verify exactly: exact_rematch_stage.h), verify each pair
// geometrically, hand the results to a writer. The stages (matching;
// verification, which first completes a rematch left to it; writing) run on
// their own threads with bounded queues, so
// the GPU matches chunk k+1 while chunk k is verified and the database
// commits chunk k-1. The stages themselves are in matching_pipeline.cc,
// what travels between them in chunk_verification.h.
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "cashash/pipeline/batch_verifier.h"
#include "cashash/pipeline/exact_rematch_stage.h"
#include "cashash/pipeline/pipeline_trace.h"
#include "cashash/matchers/feature_matcher.h"
#include "cashash/pipeline/pair_chunk_source.h"
#include "cashash/geometry/two_view_geometry.h"
#include "cashash/base/types.h"

namespace cashash {

// Where features come from (a COLMAP database in practice).
class FeatureSource {
 public:
  virtual ~FeatureSource() = default;
  // Keypoints and descriptors of one image; throws with a message naming the
  // image when its data is unusable.
  virtual ImageFeatures LoadFeatures(image_t image_id) = 0;
  // The same features for a caller that only reads them. A source that keeps
  // them in memory (GroupFeatureCache) hands out what it holds instead of a
  // copy: on a 5,000-image run the copies (1.2 MB per image at 8,192
  // features, one per image per block pair) were a third of the matching
  // thread's time. The default wraps LoadFeatures.
  virtual std::shared_ptr<const ImageFeatures> LoadSharedFeatures(image_t image_id);
  virtual const Camera& CameraOfImage(image_t image_id) const = 0;
  // How many threads should load at once. 1, the default: LoadFeatures is
  // called by one thread at a time. More: it may be called from any number
  // of threads at once. GroupFeatureCache loads with that many threads: one
  // thread reading SQLite blobs took 0.9 s for 1,000 images of 8,192
  // features, and the pipeline waited for it.
  virtual int MaxConcurrentLoads() const { return 1; }
};

struct PairResult {
  ImagePair pair;
  FeatureMatches matches;
  TwoViewGeometry geometry;
};

// Where results go. A chunk is persisted atomically: a transaction holds
// whole chunks only (one or several), so a stopped run leaves whole chunks
// behind.
class ResultSink {
 public:
  virtual ~ResultSink() = default;
  // A chunk's matches and geometries. A sink may keep the chunk's
  // transaction open for the chunks that follow (DatabaseResultSink) until
  // Flush.
  virtual void WriteChunk(const std::vector<PairResult>& results) = 0;
  // Persists every chunk written so far. The pipeline's writer calls it
  // when the run ends (finished, stopped or failed elsewhere) and when no
  // chunk has come for a while.
  virtual void Flush() {}
};

struct PipelineOptions {
  int num_threads = -1;
  // Write raw matches only; two_view_geometries rows are not written.
  bool skip_geometric_verification = false;
  TwoViewGeometryOptions two_view;
  // Chunks each queue between stages holds: matched chunks waiting for
  // verification (they hold their images' features: kPipelineBlocks in
  // schedule_sizing.h counts them) and verified chunks waiting for the
  // writer. Six, not two: chunks differ widely in cost (a diagonal chunk's
  // verification, a far chunk's writing), and with two the stages waited
  // on each other in turn (guided matching on a 1,000-image street: 7.0-7.9 s
  // with two, 5.7-6.1 s with six; exhaustive matching unchanged).
  size_t chunks_in_queue = 6;
  size_t chunks_to_write = 6;
  // Not owned; when set, every stage's interval per chunk is recorded in it
  // (pipeline_trace.h).
  PipelineTrace* trace = nullptr;
};

struct PipelineProgress {
  size_t pairs_done = 0;
  size_t pairs_total = 0;
  double elapsed_seconds = 0;
  const PairChunk* chunk = nullptr;
  double chunk_seconds = 0;
};

struct PipelineStats {
  size_t pairs_total = 0;
  size_t pairs_done = 0;
  size_t raw_matches = 0;
  size_t verified_pairs = 0;  // config >= CALIBRATED
  size_t inlier_matches = 0;
  double seconds_total = 0;
  // Busy time of each stage (loading and hashing on the loading thread,
  // matching after them on the same thread; verification and writing on
  // their own threads, overlapping the others).
  double seconds_loading = 0;  // features from the source (waits on a cache's loader too)
  double seconds_hashing = 0;  // adding images to the matcher (hash codes, device upload)
  double seconds_matching = 0;
  // Summed over the verification threads when chunks are verified
  // concurrently (verification_threads > 1), as are its waits below. It
  // includes the exact rematch left to them (ExactRematchStage).
  double seconds_verification = 0;
  double seconds_writing = 0;
  // The writer thread's CPU time within seconds_writing: the rest is time
  // it waited for a core (the other stages' threads share them) or for the
  // disk (a commit's sync).
  double seconds_writing_cpu = 0;
  // Waiting, apart from the busy times above: the matching thread for room
  // in the queue to verification (verification is slower), verification for
  // a matched chunk (matching is slower) and for room in the queue to the
  // writer, the writer for a verified chunk.
  double seconds_matching_wait_queue = 0;
  double seconds_verification_wait_input = 0;
  double seconds_verification_wait_writer = 0;
  double seconds_writing_wait_input = 0;
  bool stopped = false;  // the stop flag was raised before the end
  int verification_threads = 1;  // chunks verified at once (BatchVerifier::MaxConcurrentCalls)
  // Calls of the verification stage, each of one or more chunks
  // (BatchVerifier::ChunksPerCall): one BatchVerifier call each unless
  // verification is skipped.
  size_t verification_calls = 0;
};

class MatchingPipeline {
 public:
  MatchingPipeline(const PipelineOptions& options, FeatureSource* source, FeatureMatcher* matcher,
                   ResultSink* sink);

  // Called from the writer thread after each chunk is committed.
  void SetProgressCallback(std::function<void(const PipelineProgress&)> callback);
  // When the flag becomes true the pipeline finishes the chunks in flight,
  // commits them, and returns with stats.stopped set.
  void SetStopFlag(const std::atomic<bool>* stop);
  // Verifies each chunk with `verifier` (not owned; e.g. the GPU one)
  // instead of the default CPU thread pool over options.two_view.
  void SetBatchVerifier(BatchVerifier* verifier);
  // Rematches each chunk's pairs that may verify exactly, where and as the
  // stage's policy says (not owned; the stage's backend must be the one the
  // matcher adds its images to). None: the matcher's matches are kept.
  void SetExactRematch(ExactRematchStage* rematch);

  // Matches the chunks in order, making each when it is next (and the one
  // after it, whose images decide what stays loaded).
  PipelineStats Run(const PairChunkSource& chunks);
  PipelineStats Run(const std::vector<PairChunk>& chunks);

 private:
  PipelineOptions options_;
  FeatureSource* source_;
  FeatureMatcher* matcher_;
  ResultSink* sink_;
  std::function<void(const PipelineProgress&)> progress_;
  const std::atomic<bool>* stop_ = nullptr;
  BatchVerifier* verifier_ = nullptr;
  ExactRematchStage* rematch_ = nullptr;
};

}  // namespace cashash
