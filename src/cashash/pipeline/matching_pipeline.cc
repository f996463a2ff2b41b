#include "cashash/pipeline/matching_pipeline.h"

#include <algorithm>
#include <chrono>
#include <exception>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <unordered_set>

#include "cashash/base/thread_cpu_clock.h"
#include "cashash/pipeline/blocking_queue.h"
#include "cashash/pipeline/chunk_verification.h"
#include "cashash/pipeline/in_order_turnstile.h"

namespace cashash {
namespace {

using pipeline_internal::Clock;
using pipeline_internal::DescriptorsOf;
using pipeline_internal::KeypointsOf;
using pipeline_internal::FeaturesPtr;
using pipeline_internal::MatchedChunk;
using pipeline_internal::VerifiedChunk;
using pipeline_internal::VerifyChunks;

// How long the writer waits for a chunk before it flushes the sink.
constexpr std::chrono::milliseconds kWriterIdleFlush(500);

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Remembers the first exception thrown by any stage and makes all stages stop.
class FirstError {
 public:
  void Set(std::exception_ptr error) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!error_) error_ = error;
    failed_ = true;
  }
  bool failed() const { return failed_; }
  void RethrowIfAny() {
    if (error_) std::rethrow_exception(error_);
  }

 private:
  std::mutex mutex_;
  std::exception_ptr error_;
  std::atomic<bool> failed_{false};
};

// One run of the pipeline: the queues, the turnstile, the first
// error and the stats that its stages share, and the stages themselves, one
// function each:
//   Match   this thread: load what a chunk needs, match it;
//   Verify  the exact rematch left to it, then the batch verifier's calls, on
//           as many threads as the verifier takes calls at once;
//   Write   the single writer.
// Execute keeps the object alive until every thread is joined, which is what
// makes a failure on any stage safe to stop the others: a stage that fails
// records the error and closes the queues it shares.
class PipelineRun {
 public:
  PipelineRun(const PipelineOptions& options, FeatureSource* source, FeatureMatcher* matcher, ResultSink* sink,
              BatchVerifier* verifier, ExactRematchStage* rematch,
              const std::function<void(const PipelineProgress&)>& progress, const std::atomic<bool>* stop)
      : options_(options),
        source_(source),
        matcher_(matcher),
        sink_(sink),
        rematch_(rematch),
        progress_(progress),
        stop_(stop),
        chunks_in_queue_(std::max<size_t>(1, options.chunks_in_queue)),
        to_verify_(chunks_in_queue_),
        to_write_(std::max<size_t>(1, options.chunks_to_write)) {
    verifier_ = verifier;
    if (verifier_ == nullptr && !options_.skip_geometric_verification) {
      default_verifier_ = CreateCpuBatchVerifier(options_.two_view, options_.num_threads);
      verifier_ = default_verifier_.get();
    }
    num_verifier_threads_ = options_.skip_geometric_verification ? 1 : std::max(1, verifier_->MaxConcurrentCalls());
    verifier_threads_left_ = num_verifier_threads_;
    // A verification thread takes the chunks that wait for it, up to as many
    // as the verifier prefers, in one call: a GPU call lasts as long as its
    // slowest pair, so chunks verified together pay that tail once. The
    // extra chunks keep their room in the queue until verified, so what the
    // pipeline holds does not grow.
    chunks_per_call_ = std::max<size_t>(1, verifier_ != nullptr ? verifier_->ChunksPerCall() : 1);
  }

  PipelineStats Execute(const PairChunkSource& chunks) {
    stats_.pairs_total = chunks.num_pairs();
    stats_.verification_threads = num_verifier_threads_;
    std::thread writer(&PipelineRun::Write, this);
    std::vector<std::thread> verifier_threads;
    for (int t = 0; t < num_verifier_threads_; ++t) verifier_threads.emplace_back(&PipelineRun::Verify, this, t);
    Match(chunks);
    for (std::thread& thread : verifier_threads) thread.join();
    writer.join();
    error_.RethrowIfAny();
    if (stop_ && stop_->load() && stats_.pairs_done < stats_.pairs_total) stats_.stopped = true;
    stats_.seconds_total = SecondsSince(run_start_);
    return stats_;
  }

 private:
  // Adds the time since `start` to one of the stats' times (any thread).
  void AddSeconds(double PipelineStats::*field, Clock::time_point start) {
    const double seconds = SecondsSince(start);
    std::lock_guard<std::mutex> lock(stats_mutex_);
    stats_.*field += seconds;
  }

  // The writer's wall and CPU time since `start` and `cpu_start` (its
  // ThreadCpuSeconds then).
  void AddWriting(Clock::time_point start, double cpu_start) {
    const double seconds = SecondsSince(start);
    const double cpu = ThreadCpuSeconds() - cpu_start;
    std::lock_guard<std::mutex> lock(stats_mutex_);
    stats_.seconds_writing += seconds;
    stats_.seconds_writing_cpu += cpu;
  }

  // Records one stage's interval of one chunk when the run is traced.
  void Trace(const char* stage, size_t chunk, size_t call, int thread, Clock::time_point start, Clock::time_point end,
             size_t pairs) {
    if (options_.trace == nullptr) return;
    PipelineTraceEvent event;
    event.stage = stage;
    event.chunk = chunk;
    event.call = call;
    event.thread = thread;
    event.start = std::chrono::duration<double>(start - run_start_).count();
    event.end = std::chrono::duration<double>(end - run_start_).count();
    event.pairs = pairs;
    options_.trace->Record(std::move(event));
  }

  // Stage 1, on the caller's thread: load what the chunk needs, match.
  void Match(const PairChunkSource& chunks) {
    BlockingQueue<MatchedChunk>& after_matching = to_verify_;
    // Only a matcher that reads keypoints (guided matching) gets them.
    const bool keypoints = matcher_->traits().uses_keypoints;
    try {
      std::unordered_map<image_t, FeaturesPtr> loaded;
      // Chunks are made one ahead: the next one's images stay loaded.
      std::shared_ptr<const PairChunk> next;
      for (size_t c = 0; c < chunks.size(); ++c) {
        if (error_.failed() || (stop_ && stop_->load())) {
          stats_.stopped = !error_.failed();
          break;
        }
        const Clock::time_point chunk_start = Clock::now();
        std::shared_ptr<const PairChunk> current =
            next ? std::move(next) : std::make_shared<const PairChunk>(chunks.Chunk(c));
        next = c + 1 < chunks.size() ? std::make_shared<const PairChunk>(chunks.Chunk(c + 1)) : nullptr;
        const PairChunk& chunk = *current;

        // Drop images that neither this chunk nor the next one needs.
        std::unordered_set<image_t> keep(chunk.images.begin(), chunk.images.end());
        if (next) keep.insert(next->images.begin(), next->images.end());
        for (auto it = loaded.begin(); it != loaded.end();) {
          if (keep.count(it->first)) {
            ++it;
          } else {
            matcher_->RemoveImage(it->first);
            it = loaded.erase(it);
          }
        }
        double load_seconds = 0, hash_seconds = 0;
        for (image_t image_id : chunk.images) {
          if (loaded.count(image_id)) continue;
          const Clock::time_point t_load = Clock::now();
          FeaturesPtr features = source_->LoadSharedFeatures(image_id);
          const Clock::time_point t_hash = Clock::now();
          load_seconds += std::chrono::duration<double>(t_hash - t_load).count();
          // The matcher may keep the descriptors (aliasing the features).
          matcher_->AddImage(MatcherImage{image_id, keypoints ? KeypointsOf(features) : nullptr,
                                          DescriptorsOf(features)});
          hash_seconds += SecondsSince(t_hash);
          loaded.emplace(image_id, std::move(features));
        }

        const Clock::time_point t_match = Clock::now();
        MatchedChunk item;
        item.index = c;
        item.chunk = current;
        item.started = chunk_start;
        item.matches = matcher_->Match(chunk.pairs);
        if (rematch_ != nullptr) item.rematch = rematch_->AfterMatching(chunk.pairs, &item.matches);
        const Clock::time_point t_matched = Clock::now();
        {
          std::lock_guard<std::mutex> lock(stats_mutex_);
          stats_.seconds_loading += load_seconds;
          stats_.seconds_hashing += hash_seconds;
          stats_.seconds_matching += std::chrono::duration<double>(t_matched - t_match).count();
        }
        Trace("load", c, 0, 0, chunk_start, t_match, chunk.pairs.size());
        Trace("match", c, 0, 0, t_match, t_matched, chunk.pairs.size());
        for (image_t image_id : chunk.images) item.features.emplace(image_id, loaded.at(image_id));
        const Clock::time_point t_push = Clock::now();
        const bool pushed = after_matching.Push(std::move(item));
        AddSeconds(&PipelineStats::seconds_matching_wait_queue, t_push);
        if (!pushed) break;
      }
    } catch (...) {
      error_.Set(std::current_exception());
    }
    after_matching.Close();
  }

  // Stage 2: verification of whole chunks by the batch verifier. Chunks
  // still reach the writer in the order they were matched (the turnstile).
  void Verify(int thread) {
    // With several verification threads (a GPU verifier keeps two chunks in
    // flight), the second and later take a chunk only once the queue to
    // verification is full, that is when matching is about to wait for them,
    // or once matching has ended. While matching runs it then shares the GPU
    // with one chunk's RANSAC instead of two; the backlog and the tail are
    // still verified two at a time.
    const size_t backlog = thread > 0 ? to_verify_.capacity() : 1;
    try {
      for (;;) {
        const Clock::time_point t_wait = Clock::now();
        std::vector<MatchedChunk> items = to_verify_.PopBatch(backlog, chunks_per_call_);
        AddSeconds(&PipelineStats::seconds_verification_wait_input, t_wait);
        if (items.empty()) break;
        const Clock::time_point t0 = Clock::now();
        std::vector<VerifiedChunk> out = VerifyChunks(options_, source_, rematch_, &items, verifier_);
        to_verify_.Release(items.size() - 1);
        const Clock::time_point t_verified = Clock::now();
        size_t call = 0;
        {
          std::lock_guard<std::mutex> lock(stats_mutex_);
          stats_.seconds_verification += std::chrono::duration<double>(t_verified - t0).count();
          call = ++stats_.verification_calls;
        }
        for (const VerifiedChunk& chunk : out) {
          if (chunk.rematched) {
            Trace("rematch", chunk.index, 0, thread + 1, chunk.rematch_started, chunk.rematch_ended,
                  chunk.results->size());
          }
          Trace("verify", chunk.index, call, thread + 1, chunk.verify_started, t_verified, chunk.results->size());
        }
        // A batch's chunks are taken at once from the queue, in order.
        const Clock::time_point t_push = Clock::now();
        bool pushed = true;
        for (size_t c = 0; c < out.size() && pushed; ++c) {
          const size_t index = out[c].index;
          pushed = to_writer_in_order_.Wait(index);
          if (!pushed) break;
          pushed = to_write_.Push(std::move(out[c]));
          to_writer_in_order_.Pass(index);
        }
        AddSeconds(&PipelineStats::seconds_verification_wait_writer, t_push);
        if (!pushed) break;
      }
    } catch (...) {
      error_.Set(std::current_exception());
      to_verify_.Close();
      to_writer_in_order_.Cancel();
    }
    if (--verifier_threads_left_ == 0) to_write_.Close();
  }

  // Stage 3: the single writer. The sink may hold several chunks in one
  // transaction; it is flushed when no chunk has come for
  // kWriterIdleFlush (a chunk not yet committed is lost to a kill, and its
  // open transaction keeps other writers out) and when the run ends.
  void Write() {
    try {
      for (;;) {
        const Clock::time_point t_wait = Clock::now();
        bool idle = false;
        std::optional<VerifiedChunk> item = to_write_.PopWithin(kWriterIdleFlush, &idle);
        AddSeconds(&PipelineStats::seconds_writing_wait_input, t_wait);
        if (idle) {
          const Clock::time_point t_flush = Clock::now();
          const double cpu_flush = ThreadCpuSeconds();
          sink_->Flush();
          AddWriting(t_flush, cpu_flush);
          continue;
        }
        if (!item) break;
        const Clock::time_point t0 = Clock::now();
        const double cpu0 = ThreadCpuSeconds();
        const std::vector<PairResult>& results = *item->results;
        sink_->WriteChunk(results);
        Trace("write", item->index, 0, -1, t0, Clock::now(), results.size());
        AddWriting(t0, cpu0);
        PipelineProgress progress;
        {
          std::lock_guard<std::mutex> lock(stats_mutex_);
          stats_.pairs_done += results.size();
          for (const PairResult& r : results) {
            stats_.raw_matches += r.matches.size();
            if (r.geometry.config >= kCalibrated) {
              ++stats_.verified_pairs;
              stats_.inlier_matches += r.geometry.inlier_matches.size();
            }
          }
          progress.pairs_done = stats_.pairs_done;
        }
        progress.pairs_total = stats_.pairs_total;
        progress.elapsed_seconds = SecondsSince(run_start_);
        progress.chunk = item->chunk.get();
        progress.chunk_seconds = SecondsSince(item->started);
        if (progress_) progress_(progress);
      }
      // Finished, stopped, or another stage failed: what was written is
      // whole chunks, kept as it would have been with a commit per chunk.
      const Clock::time_point t_flush = Clock::now();
      const double cpu_flush = ThreadCpuSeconds();
      sink_->Flush();
      AddWriting(t_flush, cpu_flush);
    } catch (...) {
      error_.Set(std::current_exception());
      to_verify_.Close();
      to_write_.Close();
    }
  }

  const PipelineOptions& options_;
  FeatureSource* source_;
  FeatureMatcher* matcher_;
  ResultSink* sink_;
  ExactRematchStage* rematch_;
  const std::function<void(const PipelineProgress&)>& progress_;
  const std::atomic<bool>* stop_;
  const Clock::time_point run_start_ = Clock::now();

  const size_t chunks_in_queue_;
  BlockingQueue<MatchedChunk> to_verify_;
  BlockingQueue<VerifiedChunk> to_write_;
  InOrderTurnstile to_writer_in_order_;
  FirstError error_;

  std::unique_ptr<BatchVerifier> default_verifier_;
  BatchVerifier* verifier_ = nullptr;
  int num_verifier_threads_ = 1;
  std::atomic<int> verifier_threads_left_{1};
  size_t chunks_per_call_ = 1;

  std::mutex stats_mutex_;
  PipelineStats stats_;
};

}  // namespace

std::shared_ptr<const ImageFeatures> FeatureSource::LoadSharedFeatures(image_t image_id) {
  return std::make_shared<const ImageFeatures>(LoadFeatures(image_id));
}

MatchingPipeline::MatchingPipeline(const PipelineOptions& options, FeatureSource* source,
                                   FeatureMatcher* matcher, ResultSink* sink)
    : options_(options), source_(source), matcher_(matcher), sink_(sink) {}

void MatchingPipeline::SetProgressCallback(std::function<void(const PipelineProgress&)> callback) {
  progress_ = std::move(callback);
}

void MatchingPipeline::SetStopFlag(const std::atomic<bool>* stop) { stop_ = stop; }

void MatchingPipeline::SetBatchVerifier(BatchVerifier* verifier) { verifier_ = verifier; }

void MatchingPipeline::SetExactRematch(ExactRematchStage* rematch) { rematch_ = rematch; }

PipelineStats MatchingPipeline::Run(const PairChunkSource& chunks) {
  PipelineRun run(options_, source_, matcher_, sink_, verifier_, rematch_, progress_, stop_);
  return run.Execute(chunks);
}

PipelineStats MatchingPipeline::Run(const std::vector<PairChunk>& chunks) { return Run(ChunkList(&chunks)); }

}  // namespace cashash
