// The matching pipeline: load features of a chunk of pairs, match them with a
// FeatureMatcher backend, verify each pair geometrically, hand the results to
// a writer. The stages (matching; optionally what the matcher deferred;
// verification; writing) run on their own threads with bounded queues, so
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
#include "cashash/pipeline/pipeline_trace.h"
#include "cashash/matchers/feature_matcher.h"
#include "cashash/pipeline/pair_generation.h"
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

// Where results go. WriteChunk persists a chunk atomically (one
// transaction), so a stopped run leaves only whole chunks behind.
class ResultSink {
 public:
  virtual ~ResultSink() = default;
  // A chunk's matches and geometries, in one transaction.
  virtual void WriteChunk(const std::vector<PairResult>& results) = 0;

  // A chunk in two steps instead: its raw matches as soon as they are final
  // (while the chunk is verified), then its geometries, each step in a
  // transaction of its own. Only for a sink where a chunk whose second step
  // never came looks unfinished to a rerun (which matches its pairs again),
  // so that a run stopped between the two steps resumes like one stopped
  // anywhere else. The pipeline calls these only when this says so.
  virtual bool WritesMatchesAhead() const { return false; }
  virtual void WriteMatchesAhead(const std::vector<PairResult>& results) {}
  virtual void WriteGeometries(const std::vector<PairResult>& results) { WriteChunk(results); }
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
  // With several verification threads (a GPU verifier keeps two chunks in
  // flight), the second and later take a chunk only once the queue to
  // verification is full, that is when matching is about to wait for them,
  // or once matching has ended. While matching runs it then shares the GPU
  // with one chunk's RANSAC instead of two; the backlog and the tail are
  // still verified two at a time. false: every thread takes chunks at once.
  bool extra_verifiers_on_backlog = true;
  // Most matched chunks one verifier call takes: a verification thread takes
  // the chunks that wait for it, up to this many, in one BatchVerifier call.
  // A GPU call lasts as long as its slowest pair, so chunks verified
  // together pay that tail once. The extra chunks keep their room in the
  // queue until verified, so what the pipeline holds does not grow. 1: one
  // chunk per call; 0: as the verifier prefers (BatchVerifier::ChunksPerCall).
  size_t chunks_per_verification = 0;
  // Hand a chunk's raw matches to the writer once they are final (after
  // the exact rematch, before the verifier call), when the sink can take
  // them ahead (ResultSink::WritesMatchesAhead): the writer, idle while
  // chunks are verified, writes them then, and after verification only the
  // geometries are left. A run ends with the writes of its last verified
  // chunks; on the 300-image street that was 0.05-0.10 s with the device
  // idle (device run 121's traces), and two_view_geometries rows are 44-75 %
  // of a chunk's writing (write_rows_bench --two_steps 1). Ignored when
  // verification is skipped. Off: on one H100 (device run 125) it halved
  // the writer's time alone at the end, but the run was no shorter (the
  // cascade's run is bound by the device's total work), and it lets a
  // reader see a chunk's matches before its geometries.
  bool write_matches_ahead = false;
  // Complete what the matcher deferred (the GPU cascade's exact rematch) on
  // a thread of its own between matching and verification, instead of on
  // the verification threads before their verifier calls. Where
  // verification sets the pace (the GPU cascade at 300 images: rematch and
  // verification busy from their first start to the end of device work),
  // the rematch then stops adding to that stage: device run 121's traces
  // have 0.22 s of rematch in a 0.70 s verification stage. The queue to
  // verification is then two chunks shorter (one waits for that thread, one
  // is on it). Ignored when verification is skipped. Off: on one H100
  // (device run 125) the rematch then ran beside the matching kernels and
  // both slowed (matching busy +0.15 s, rematch +0.09 s at 8,192 features),
  // so the run was no shorter.
  bool deferred_matching_thread = false;
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
  // includes what the matcher deferred to them (the GPU's exact rematch),
  // unless that has a thread of its own (deferred_matching_thread).
  double seconds_verification = 0;
  double seconds_writing = 0;
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
  // (chunks_per_verification): one BatchVerifier call each unless
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

  PipelineStats Run(const std::vector<PairChunk>& chunks);

 private:
  PipelineOptions options_;
  FeatureSource* source_;
  FeatureMatcher* matcher_;
  ResultSink* sink_;
  std::function<void(const PipelineProgress&)> progress_;
  const std::atomic<bool>* stop_ = nullptr;
  BatchVerifier* verifier_ = nullptr;
};

// Verifies one pair (exposed for tests and for the verify-only mode).
TwoViewGeometry VerifyPair(const Camera& camera1, const ImageFeatures& image1, const Camera& camera2,
                           const ImageFeatures& image2, const FeatureMatches& matches,
                           const TwoViewGeometryOptions& options);

}  // namespace cashash
