#include "cashash/pipeline/matching_pipeline.h"

#include <algorithm>
#include <chrono>
#include <exception>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <unordered_set>

#include "cashash/pipeline/blocking_queue.h"
#include "cashash/pipeline/in_order_turnstile.h"
#include "cashash/base/pair_id.h"
#include "cashash/pipeline/thread_pool.h"

namespace cashash {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

using FeaturesPtr = std::shared_ptr<const ImageFeatures>;

// An image's descriptors, sharing ownership of its features.
std::shared_ptr<const FeatureDescriptors> DescriptorsOf(const FeaturesPtr& features) {
  return std::shared_ptr<const FeatureDescriptors>(features, &features->descriptors);
}

// What travels from the matching stage to the verification stage.
struct MatchedChunk {
  size_t index = 0;  // position in the run's chunks: the writer's order
  const PairChunk* chunk = nullptr;
  std::unordered_map<image_t, FeaturesPtr> features;
  std::vector<FeatureMatches> matches;
  // What the matcher left to complete the matches (the exact rematch on the
  // GPU): done on the verification thread, before verifying.
  std::unique_ptr<DeferredMatching> deferred;
  Clock::time_point started;
};

struct VerifiedChunk {
  size_t index = 0;
  const PairChunk* chunk = nullptr;
  // Shared with the chunk's matches-ahead item (write_matches_ahead), which
  // the writer may write while the verifier fills in the geometries: the
  // two read and write different members of each PairResult.
  std::shared_ptr<std::vector<PairResult>> results = std::make_shared<std::vector<PairResult>>();
  // A matches-ahead item: only the raw matches are written, and the chunk
  // comes again, verified (with matches_written set), later in the queue.
  bool matches_only = false;
  bool matches_written = false;
  Clock::time_point started;
  // For the trace: the chunk's deferred matching, if it had any, and when
  // its verifier call started.
  bool rematched = false;
  Clock::time_point rematch_started, rematch_ended, verify_started;
};

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

// Completes what the matcher deferred for `item` (the GPU's exact rematch),
// if anything; returns whether there was something.
bool CompleteDeferred(MatchedChunk* item) {
  if (!item->deferred) return false;
  item->deferred->Complete([&](image_t image_id) { return DescriptorsOf(item->features.at(image_id)); },
                           &item->matches);
  item->deferred.reset();
  return true;
}

// The verification of matched chunks in one call of the verifier: for each
// chunk what the matcher deferred first, then results in the chunk's pair
// order, geometries left undefined when verification is skipped. One call
// for several chunks because a GPU call lasts as long as its slowest pair:
// chunks that wait together share that tail instead of paying it in turn.
// Releases the chunks' features. `matches_final`, when set, is given each
// chunk once its matches are final, before the verifier call, and says
// whether it took them (to write them ahead).
std::vector<VerifiedChunk> VerifyChunks(const PipelineOptions& options, FeatureSource* source,
                                        std::vector<MatchedChunk>* items, BatchVerifier* verifier,
                                        const std::function<bool(const VerifiedChunk&)>& matches_final) {
  std::vector<VerifiedChunk> out(items->size());
  for (size_t c = 0; c < items->size(); ++c) {
    MatchedChunk& item = (*items)[c];
    out[c].index = item.index;
    out[c].chunk = item.chunk;
    out[c].started = item.started;
    out[c].rematch_started = Clock::now();
    out[c].rematched = CompleteDeferred(&item);
    out[c].rematch_ended = Clock::now();
    const std::vector<ImagePair>& pairs = item.chunk->pairs;
    std::vector<PairResult>& results = *out[c].results;
    results.resize(pairs.size());
    for (size_t k = 0; k < pairs.size(); ++k) {
      results[k].pair = pairs[k];
      results[k].matches = std::move(item.matches[k]);
    }
    if (matches_final && !options.skip_geometric_verification) out[c].matches_written = matches_final(out[c]);
  }
  const Clock::time_point verify_started = Clock::now();
  for (VerifiedChunk& chunk : out) chunk.verify_started = verify_started;
  if (!options.skip_geometric_verification) {
    // Keypoint positions once per image of the chunks, not once per pair.
    std::unordered_map<image_t, std::vector<Eigen::Vector2d>> positions;
    std::vector<std::pair<std::vector<Eigen::Vector2d>*, const ImageFeatures*>> to_fill;
    for (const MatchedChunk& item : *items) {
      for (const auto& entry : item.features) {
        const auto slot = positions.emplace(entry.first, std::vector<Eigen::Vector2d>());
        if (slot.second) to_fill.emplace_back(&slot.first->second, entry.second.get());
      }
    }
    ParallelFor(to_fill.size(), options.num_threads,
                [&](size_t i) { *to_fill[i].first = KeypointPositions(to_fill[i].second->keypoints); });
    std::vector<VerificationPair> tasks;
    for (VerifiedChunk& chunk : out) {
      for (PairResult& result : *chunk.results) {
        VerificationPair task;
        task.camera1 = &source->CameraOfImage(result.pair.first);
        task.camera2 = &source->CameraOfImage(result.pair.second);
        task.points1 = &positions.at(result.pair.first);
        task.points2 = &positions.at(result.pair.second);
        task.matches = &result.matches;
        task.random_seed = PairRandomSeed(options.two_view.random_seed, result.pair);
        tasks.push_back(task);
      }
    }
    std::vector<TwoViewGeometry> geometries = verifier->Verify(tasks);
    size_t next = 0;
    for (VerifiedChunk& chunk : out) {
      for (PairResult& result : *chunk.results) result.geometry = std::move(geometries[next++]);
    }
  }
  for (MatchedChunk& item : *items) item.features.clear();
  return out;
}

// Holds verification back while the matcher chooses its backend (see
// FeatureMatcher::ChoosingBackend). Device run 25 timed the cascade at
// 0.56 ms per pair instead of 0.016 while the first chunk's RANSAC filled
// the GPU, and auto chose brute force, 3x slower over the run; verification
// has time to spare at the start, and the queue keeps the chunks.
class VerificationGate {
 public:
  void Open() {
    std::lock_guard<std::mutex> lock(mutex_);
    open_ = true;
    opened_.notify_all();
  }
  void Wait() {
    std::unique_lock<std::mutex> lock(mutex_);
    opened_.wait(lock, [&] { return open_; });
  }

 private:
  std::mutex mutex_;
  std::condition_variable opened_;
  bool open_ = false;
};

}  // namespace

TwoViewGeometry VerifyPair(const Camera& camera1, const ImageFeatures& image1, const Camera& camera2,
                           const ImageFeatures& image2, const FeatureMatches& matches,
                           const TwoViewGeometryOptions& options) {
  return EstimateTwoViewGeometry(camera1, KeypointPositions(image1.keypoints), camera2,
                                 KeypointPositions(image2.keypoints), matches, options);
}

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

// One function because its three stages (the writer thread, the verifier
// threads, matching on this thread) are lambdas over one scope: the queues,
// the turnstile, the gate, the first error and the stats' lock they share
// live exactly until the joins at the end, which is what makes a failure on
// any stage safe to stop the others.
PipelineStats MatchingPipeline::Run(const std::vector<PairChunk>& chunks) {
  PipelineStats stats;
  for (const PairChunk& chunk : chunks) stats.pairs_total += chunk.pairs.size();
  const Clock::time_point run_start = Clock::now();

  const size_t chunks_in_queue = std::max<size_t>(1, options_.chunks_in_queue);
  // With a thread for the deferred matching, one chunk waits for it and one
  // is on it: the queue to verification gives up that room, so that no more
  // chunks are held than without it (kPipelineBlocks counts them).
  const bool deferred_stage = options_.deferred_matching_thread && !options_.skip_geometric_verification;
  BlockingQueue<MatchedChunk> to_complete(1);
  BlockingQueue<MatchedChunk> to_verify(deferred_stage ? std::max<size_t>(1, chunks_in_queue - 2) : chunks_in_queue);
  BlockingQueue<VerifiedChunk> to_write(std::max<size_t>(1, options_.chunks_to_write));
  FirstError error;
  std::mutex stats_mutex;
  // Adds the time since `start` to one of the stats' times (any thread).
  auto add_seconds = [&](double PipelineStats::*field, Clock::time_point start) {
    const double seconds = SecondsSince(start);
    std::lock_guard<std::mutex> lock(stats_mutex);
    stats.*field += seconds;
  };

  // Records one stage's interval of one chunk when the run is traced.
  auto trace = [&](const char* stage, size_t chunk, size_t call, int thread, Clock::time_point start,
                   Clock::time_point end, size_t pairs) {
    if (options_.trace == nullptr) return;
    PipelineTraceEvent event;
    event.stage = stage;
    event.chunk = chunk;
    event.call = call;
    event.thread = thread;
    event.start = std::chrono::duration<double>(start - run_start).count();
    event.end = std::chrono::duration<double>(end - run_start).count();
    event.pairs = pairs;
    options_.trace->Record(std::move(event));
  };

  // Stage 3: the single writer.
  std::thread writer([&]() {
    try {
      for (;;) {
        const Clock::time_point t_wait = Clock::now();
        std::optional<VerifiedChunk> item = to_write.Pop();
        add_seconds(&PipelineStats::seconds_writing_wait_input, t_wait);
        if (!item) break;
        const Clock::time_point t0 = Clock::now();
        const std::vector<PairResult>& results = *item->results;
        if (item->matches_only) {
          sink_->WriteMatchesAhead(results);
          trace("write_ahead", item->index, 0, -1, t0, Clock::now(), results.size());
          add_seconds(&PipelineStats::seconds_writing, t0);
          continue;
        }
        if (item->matches_written) {
          sink_->WriteGeometries(results);
        } else {
          sink_->WriteChunk(results);
        }
        trace("write", item->index, 0, -1, t0, Clock::now(), results.size());
        PipelineProgress progress;
        {
          std::lock_guard<std::mutex> lock(stats_mutex);
          stats.seconds_writing += SecondsSince(t0);
          stats.pairs_done += results.size();
          for (const PairResult& r : results) {
            stats.raw_matches += r.matches.size();
            if (r.geometry.config >= kCalibrated) {
              ++stats.verified_pairs;
              stats.inlier_matches += r.geometry.inlier_matches.size();
            }
          }
          progress.pairs_done = stats.pairs_done;
        }
        progress.pairs_total = stats.pairs_total;
        progress.elapsed_seconds = SecondsSince(run_start);
        progress.chunk = item->chunk;
        progress.chunk_seconds = SecondsSince(item->started);
        if (progress_) progress_(progress);
      }
    } catch (...) {
      error.Set(std::current_exception());
      to_complete.Close();
      to_verify.Close();
      to_write.Close();
    }
  });

  // Stage 2: verification of whole chunks by the batch verifier, on as many
  // threads as it takes calls at once. Chunks still reach the writer in the
  // order they were matched (the turnstile).
  std::unique_ptr<BatchVerifier> default_verifier;
  BatchVerifier* verifier = verifier_;
  if (verifier == nullptr && !options_.skip_geometric_verification) {
    default_verifier = CreateCpuBatchVerifier(options_.two_view, options_.num_threads);
    verifier = default_verifier.get();
  }
  const int num_verifier_threads =
      options_.skip_geometric_verification ? 1 : std::max(1, verifier->MaxConcurrentCalls());
  stats.verification_threads = num_verifier_threads;
  InOrderTurnstile to_writer_in_order;
  VerificationGate gate;
  std::atomic<int> verifier_threads_left{num_verifier_threads};
  size_t chunks_per_call = options_.chunks_per_verification;
  if (chunks_per_call == 0) chunks_per_call = verifier != nullptr ? verifier->ChunksPerCall() : 1;
  chunks_per_call = std::max<size_t>(1, chunks_per_call);
  // The writer takes a chunk's raw matches ahead of its verified rows: the
  // item goes before the chunk's own (same queue, pushed earlier) and never
  // waits for room, so the verifier call is not held up by the writer.
  const bool write_ahead = options_.write_matches_ahead && sink_->WritesMatchesAhead();
  std::function<bool(const VerifiedChunk&)> matches_final;
  if (write_ahead) {
    matches_final = [&](const VerifiedChunk& chunk) {
      VerifiedChunk ahead;
      ahead.index = chunk.index;
      ahead.chunk = chunk.chunk;
      ahead.results = chunk.results;
      ahead.matches_only = true;
      return to_write.PushWithoutWaiting(std::move(ahead));
    };
  }
  auto verification_stage = [&](int thread) {
    // A helper (the second thread on) waits for a full queue or the end.
    const size_t backlog = thread > 0 && options_.extra_verifiers_on_backlog ? to_verify.capacity() : 1;
    try {
      for (;;) {
        const Clock::time_point t_wait = Clock::now();
        gate.Wait();
        std::vector<MatchedChunk> items = to_verify.PopBatch(backlog, chunks_per_call);
        add_seconds(&PipelineStats::seconds_verification_wait_input, t_wait);
        if (items.empty()) break;
        const Clock::time_point t0 = Clock::now();
        std::vector<VerifiedChunk> out = VerifyChunks(options_, source_, &items, verifier, matches_final);
        to_verify.Release(items.size() - 1);
        const Clock::time_point t_verified = Clock::now();
        size_t call = 0;
        {
          std::lock_guard<std::mutex> lock(stats_mutex);
          stats.seconds_verification += std::chrono::duration<double>(t_verified - t0).count();
          call = ++stats.verification_calls;
        }
        for (const VerifiedChunk& chunk : out) {
          if (chunk.rematched) {
            trace("rematch", chunk.index, 0, thread + 1, chunk.rematch_started, chunk.rematch_ended,
                  chunk.results->size());
          }
          trace("verify", chunk.index, call, thread + 1, chunk.verify_started, t_verified, chunk.results->size());
        }
        // The batch's chunks are consecutive: the queue is one producer's,
        // in order, and a batch is taken at once.
        const Clock::time_point t_push = Clock::now();
        bool pushed = true;
        for (size_t c = 0; c < out.size() && pushed; ++c) {
          const size_t index = out[c].index;
          pushed = to_writer_in_order.Wait(index);
          if (!pushed) break;
          pushed = to_write.Push(std::move(out[c]));
          to_writer_in_order.Pass(index);
        }
        add_seconds(&PipelineStats::seconds_verification_wait_writer, t_push);
        if (!pushed) break;
      }
    } catch (...) {
      error.Set(std::current_exception());
      to_complete.Close();
      to_verify.Close();
      to_writer_in_order.Cancel();
    }
    if (--verifier_threads_left == 0) to_write.Close();
  };
  std::vector<std::thread> verifier_threads;
  for (int t = 0; t < num_verifier_threads; ++t) verifier_threads.emplace_back(verification_stage, t);

  // Stage 1b (deferred_matching_thread): what the matcher deferred, on a
  // thread of its own, in matching order. Ends by closing the queue to
  // verification; a failure closes both of its queues, so that matching
  // stops instead of waiting for room.
  std::thread completer;
  if (deferred_stage) {
    completer = std::thread([&]() {
      try {
        for (;;) {
          std::optional<MatchedChunk> item = to_complete.Pop();
          if (!item) break;
          const Clock::time_point t0 = Clock::now();
          if (CompleteDeferred(&*item)) trace("rematch", item->index, 0, -2, t0, Clock::now(), item->chunk->pairs.size());
          if (!to_verify.Push(std::move(*item))) break;
        }
      } catch (...) {
        error.Set(std::current_exception());
      }
      to_complete.Close();
      to_verify.Close();
    });
  }
  BlockingQueue<MatchedChunk>& after_matching = deferred_stage ? to_complete : to_verify;

  // Stage 1 (this thread): load what the chunk needs, match. The gate opens
  // once the matcher has chosen, or before a push that could wait for
  // verification (the queue full), or when matching ends.
  size_t pushed_while_gated = 0;
  try {
    std::unordered_map<image_t, FeaturesPtr> loaded;
    for (size_t c = 0; c < chunks.size(); ++c) {
      if (error.failed() || (stop_ && stop_->load())) {
        stats.stopped = !error.failed();
        break;
      }
      const PairChunk& chunk = chunks[c];
      const Clock::time_point chunk_start = Clock::now();

      // Drop images that neither this chunk nor the next one needs.
      std::unordered_set<image_t> keep(chunk.images.begin(), chunk.images.end());
      if (c + 1 < chunks.size()) keep.insert(chunks[c + 1].images.begin(), chunks[c + 1].images.end());
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
        matcher_->AddSharedImage(image_id, DescriptorsOf(features));
        hash_seconds += SecondsSince(t_hash);
        loaded.emplace(image_id, std::move(features));
      }

      const Clock::time_point t_match = Clock::now();
      MatchedChunk item;
      item.index = c;
      item.chunk = &chunk;
      item.started = chunk_start;
      ChunkMatches matched = matcher_->MatchPairsDeferred(chunk.pairs);
      item.matches = std::move(matched.matches);
      item.deferred = std::move(matched.deferred);
      const Clock::time_point t_matched = Clock::now();
      {
        std::lock_guard<std::mutex> lock(stats_mutex);
        stats.seconds_loading += load_seconds;
        stats.seconds_hashing += hash_seconds;
        stats.seconds_matching += std::chrono::duration<double>(t_matched - t_match).count();
      }
      trace("load", c, 0, 0, chunk_start, t_match, chunk.pairs.size());
      trace("match", c, 0, 0, t_match, t_matched, chunk.pairs.size());
      for (image_t image_id : chunk.images) item.features.emplace(image_id, loaded.at(image_id));
      if (!matcher_->ChoosingBackend() || pushed_while_gated >= chunks_in_queue) gate.Open();
      ++pushed_while_gated;
      const Clock::time_point t_push = Clock::now();
      const bool pushed = after_matching.Push(std::move(item));
      add_seconds(&PipelineStats::seconds_matching_wait_queue, t_push);
      if (!pushed) break;
    }
  } catch (...) {
    error.Set(std::current_exception());
  }
  gate.Open();
  after_matching.Close();
  if (completer.joinable()) completer.join();
  for (std::thread& thread : verifier_threads) thread.join();
  writer.join();
  error.RethrowIfAny();
  if (stop_ && stop_->load() && stats.pairs_done < stats.pairs_total) stats.stopped = true;
  stats.seconds_total = SecondsSince(run_start);
  return stats;
}

}  // namespace cashash
