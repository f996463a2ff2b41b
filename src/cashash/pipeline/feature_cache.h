// The host-memory level of the three-level scheduling: a FeatureSource that
// keeps the features of the current group pair in memory and loads the next
// one on its own thread while the current one is matched.
//
// The run's chunks (ScheduledChunkSource, possibly thinned by resume) are
// cut into steps: runs of chunks of one group pair. A chunk whose images are all
// held already (a diagonal group pair after the cross pair that brought its
// group) joins the running step. A step holds the images its chunks touch;
// while the pipeline works on step s, the cache holds step s and loads step
// s + 1 -- at most three groups -- and forgets what neither needs.
//
// The pipeline asks for the images of its chunks in chunk order; the first
// request for an image the current step does not hold moves the cache to
// the next step holding it. A request the cache cannot serve (an order it
// did not plan) goes to the wrapped source directly: slower, never wrong.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <exception>
#include <memory>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <vector>

#include "cashash/pipeline/matching_pipeline.h"

namespace cashash {

// Bytes one image's features take in host memory.
size_t FeatureBytes(const ImageFeatures& features);

struct FeatureCacheStats {
  size_t source_loads = 0;     // LoadFeatures calls on the wrapped source
  size_t served = 0;           // requests answered from memory
  size_t unplanned = 0;        // requests passed to the source directly
  size_t peak_bytes = 0;       // most bytes of features held at once
  size_t steps = 0;
};

class GroupFeatureCache : public FeatureSource {
 public:
  // `source` must outlive the cache; it is called from the cache's loading
  // threads (MaxConcurrentLoads() of them) and, for unplanned requests, from
  // the caller's thread; one at a time where MaxConcurrentLoads() is 1.
  // The steps are planned from the chunks' outlines (PairChunkSource::
  // Outline) in one pass; the chunks need not outlive the cache.
  GroupFeatureCache(FeatureSource* source, const PairChunkSource& chunks);
  GroupFeatureCache(FeatureSource* source, const std::vector<PairChunk>& chunks);
  ~GroupFeatureCache() override;
  GroupFeatureCache(const GroupFeatureCache&) = delete;
  GroupFeatureCache& operator=(const GroupFeatureCache&) = delete;

  // Errors of the loading thread are rethrown here, for the image asked for.
  ImageFeatures LoadFeatures(image_t image_id) override;
  // What the cache holds, without a copy.
  std::shared_ptr<const ImageFeatures> LoadSharedFeatures(image_t image_id) override;
  const Camera& CameraOfImage(image_t image_id) const override;

  FeatureCacheStats stats() const;

  // The steps the chunks are cut into (images in first-use order); exposed
  // for tests and for memory estimates.
  static std::vector<std::vector<image_t>> Steps(const PairChunkSource& chunks);
  static std::vector<std::vector<image_t>> Steps(const std::vector<PairChunk>& chunks);

 private:
  using FeaturesPtr = std::shared_ptr<const ImageFeatures>;

  void LoaderLoop();
  // Loads the images of step s not held yet, with the source's concurrent
  // loads; called and returns with `lock` held.
  void LoadStep(int s, std::unique_lock<std::mutex>& lock);
  // One LoadFeatures call, serialised unless the source allows concurrent ones.
  ImageFeatures LoadFromSource(image_t image_id);
  ImageFeatures LoadDirectly(image_t image_id);
  // Smallest step >= from that holds the image, or -1.
  int StepHolding(image_t image_id, int from) const;
  bool InStep(image_t image_id, int step) const;

  FeatureSource* source_;
  std::mutex source_mutex_;  // serialises a source that allows one load at a time
  int loader_threads_ = 1;   // the source's MaxConcurrentLoads
  std::vector<std::vector<image_t>> steps_;
  // The steps of each image, ascending: also what tells whether a step holds
  // an image, so that the plan costs a few bytes per image and step (a set
  // per step cost about ten times that, and a run has about
  // groups^2 / 2 steps).
  std::unordered_map<image_t, std::vector<int>> steps_of_image_;

  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::unordered_map<image_t, FeaturesPtr> held_;
  size_t held_bytes_ = 0;
  int current_step_ = 0;     // where the pipeline is
  int loading_step_ = -1;    // what the loader works on (or finished last)
  bool loading_done_ = false;  // loading_step_ is complete
  std::unordered_map<image_t, std::exception_ptr> failed_;  // load errors by image
  bool stopping_ = false;
  FeatureCacheStats stats_;
  std::thread loader_;
};

}  // namespace cashash
