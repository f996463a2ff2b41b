#include "cashash/pipeline/feature_cache.h"

#include <algorithm>
#include <atomic>
#include <system_error>
#include <utility>

namespace cashash {

size_t FeatureBytes(const ImageFeatures& features) {
  return features.descriptors.data.size() + features.keypoints.size() * sizeof(Keypoint);
}

std::vector<std::vector<image_t>> GroupFeatureCache::Steps(const std::vector<PairChunk>& chunks) {
  return Steps(ChunkList(&chunks));
}

namespace {

// The step an image was last added to (-1: none): a flat table for ids up
// to 2^24 (COLMAP numbers images 1..n), a map beyond. Planning visits every
// image of every chunk (8 million at 20,000 images in blocks of 50), so
// the common case is an array read, not a hash lookup.
class LastStepOfImage {
 public:
  int Get(image_t id) const {
    if (id < kFlatIds) return id < flat_.size() ? flat_[id] : -1;
    const auto it = far_.find(id);
    return it == far_.end() ? -1 : it->second;
  }
  void Set(image_t id, int step) {
    if (id >= kFlatIds) {
      far_[id] = step;
      return;
    }
    if (id >= flat_.size()) flat_.resize(std::min<size_t>(std::max<size_t>(id + 1, 2 * flat_.size()), kFlatIds), -1);
    flat_[id] = step;
  }

 private:
  static constexpr image_t kFlatIds = image_t{1} << 24;
  std::vector<int> flat_;
  std::unordered_map<image_t, int> far_;
};

}  // namespace

std::vector<std::vector<image_t>> GroupFeatureCache::Steps(const PairChunkSource& chunks) {
  std::vector<std::vector<image_t>> steps;
  LastStepOfImage last_step;
  std::pair<int, int> group_pair(-1, -1);
  for (size_t k = 0; k < chunks.size(); ++k) {
    const PairChunk chunk = chunks.Outline(k);
    const std::pair<int, int> chunk_groups(chunk.group_i, chunk.group_j);
    const int step = static_cast<int>(steps.size()) - 1;
    if (steps.empty() || (chunk_groups != group_pair &&
                          !std::all_of(chunk.images.begin(), chunk.images.end(),
                                       [&](image_t id) { return last_step.Get(id) == step; }))) {
      steps.emplace_back();
    }
    group_pair = chunk_groups;
    const int current = static_cast<int>(steps.size()) - 1;
    for (image_t id : chunk.images) {
      if (last_step.Get(id) == current) continue;
      last_step.Set(id, current);
      steps.back().push_back(id);
    }
  }
  return steps;
}

GroupFeatureCache::GroupFeatureCache(FeatureSource* source, const std::vector<PairChunk>& chunks)
    : GroupFeatureCache(source, ChunkList(&chunks)) {}

GroupFeatureCache::GroupFeatureCache(FeatureSource* source, const PairChunkSource& chunks)
    : source_(source), loader_threads_(std::max(1, source->MaxConcurrentLoads())), steps_(Steps(chunks)) {
  for (size_t s = 0; s < steps_.size(); ++s) {
    for (image_t id : steps_[s]) steps_of_image_[id].push_back(static_cast<int>(s));
  }
  stats_.steps = steps_.size();
  if (!steps_.empty()) loader_ = std::thread([this]() { LoaderLoop(); });
}

GroupFeatureCache::~GroupFeatureCache() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  changed_.notify_all();
  if (loader_.joinable()) loader_.join();
}

bool GroupFeatureCache::InStep(image_t image_id, int step) const {
  const auto it = steps_of_image_.find(image_id);
  return it != steps_of_image_.end() && std::binary_search(it->second.begin(), it->second.end(), step);
}

int GroupFeatureCache::StepHolding(image_t image_id, int from) const {
  const auto it = steps_of_image_.find(image_id);
  if (it == steps_of_image_.end()) return -1;
  const auto step = std::lower_bound(it->second.begin(), it->second.end(), from);
  return step == it->second.end() ? -1 : *step;
}

void GroupFeatureCache::LoaderLoop() {
  const int num_steps = static_cast<int>(steps_.size());
  std::unique_lock<std::mutex> lock(mutex_);
  for (int s = 0;; ++s) {
    // Load step s once the pipeline works on step s - 1: the current step
    // and the next are held, never more.
    changed_.wait(lock, [&]() { return stopping_ || current_step_ >= s - 1; });
    if (stopping_) break;
    s = std::max(s, current_step_);  // the pipeline skipped ahead
    if (s >= num_steps) break;
    // Keep steps s - 1 and s (the pipeline is on one of them), whether the
    // loader runs ahead of the pipeline or behind it, so that what is read
    // again does not depend on timing.
    for (auto it = held_.begin(); it != held_.end();) {
      if ((s > 0 && InStep(it->first, s - 1)) || InStep(it->first, s)) {
        ++it;
      } else {
        held_bytes_ -= FeatureBytes(*it->second);
        it = held_.erase(it);
      }
    }
    loading_step_ = s;
    loading_done_ = false;
    LoadStep(s, lock);
    loading_done_ = true;
    changed_.notify_all();
  }
  // Nothing more will be loaded: waiting requests go to the source.
  loading_step_ = num_steps;
  loading_done_ = true;
  changed_.notify_all();
}

void GroupFeatureCache::LoadStep(int s, std::unique_lock<std::mutex>& lock) {
  // Images in first-use order: each loader takes the next one, so the
  // pipeline's next image is the next to arrive, whichever thread reads it.
  std::vector<image_t> todo;
  for (image_t id : steps_[s]) {
    if (!held_.count(id)) todo.push_back(id);
  }
  lock.unlock();
  std::atomic<size_t> next{0};
  auto load = [&]() {
    for (size_t i = next++; i < todo.size(); i = next++) {
      {
        std::lock_guard<std::mutex> guard(mutex_);
        if (stopping_ || current_step_ > s) return;
      }
      FeaturesPtr features;
      std::exception_ptr error;
      try {
        features = std::make_shared<const ImageFeatures>(LoadFromSource(todo[i]));
      } catch (...) {
        error = std::current_exception();
      }
      std::lock_guard<std::mutex> guard(mutex_);
      ++stats_.source_loads;
      if (error) {
        failed_[todo[i]] = error;
      } else {
        held_bytes_ += FeatureBytes(*features);
        stats_.peak_bytes = std::max(stats_.peak_bytes, held_bytes_);
        held_.emplace(todo[i], std::move(features));
      }
      changed_.notify_all();
    }
  };
  const int helpers_wanted = std::min<int>(loader_threads_, static_cast<int>(todo.size())) - 1;
  std::vector<std::thread> helpers;
  try {
    for (int t = 0; t < helpers_wanted; ++t) helpers.emplace_back(load);
  } catch (const std::system_error&) {
    // No thread to be had: the helpers that started and this one load all.
  }
  load();
  for (std::thread& helper : helpers) helper.join();
  lock.lock();
}

ImageFeatures GroupFeatureCache::LoadFromSource(image_t image_id) {
  if (loader_threads_ > 1) return source_->LoadFeatures(image_id);
  std::lock_guard<std::mutex> source_lock(source_mutex_);
  return source_->LoadFeatures(image_id);
}

ImageFeatures GroupFeatureCache::LoadDirectly(image_t image_id) {
  ImageFeatures features = LoadFromSource(image_id);
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.source_loads;
  ++stats_.unplanned;
  return features;
}

ImageFeatures GroupFeatureCache::LoadFeatures(image_t image_id) {
  return *LoadSharedFeatures(image_id);  // the copy is made outside the lock
}

std::shared_ptr<const ImageFeatures> GroupFeatureCache::LoadSharedFeatures(image_t image_id) {
  FeaturesPtr features;
  {
    std::unique_lock<std::mutex> lock(mutex_);
    if (steps_.empty()) {
      lock.unlock();
      return std::make_shared<const ImageFeatures>(LoadDirectly(image_id));
    }
    if (!InStep(image_id, current_step_)) {
      const int step = StepHolding(image_id, current_step_ + 1);
      if (step < 0) {
        lock.unlock();
        return std::make_shared<const ImageFeatures>(LoadDirectly(image_id));
      }
      current_step_ = step;
      changed_.notify_all();
    }
    changed_.wait(lock, [&]() {
      return held_.count(image_id) || failed_.count(image_id) || loading_step_ > current_step_ ||
             (loading_step_ == current_step_ && loading_done_);
    });
    const auto failed = failed_.find(image_id);
    if (failed != failed_.end()) {
      const std::exception_ptr error = failed->second;
      failed_.erase(failed);
      std::rethrow_exception(error);
    }
    const auto held = held_.find(image_id);
    if (held != held_.end()) {
      features = held->second;
      ++stats_.served;
    }
  }
  if (!features) return std::make_shared<const ImageFeatures>(LoadDirectly(image_id));
  return features;
}

const Camera& GroupFeatureCache::CameraOfImage(image_t image_id) const { return source_->CameraOfImage(image_id); }

FeatureCacheStats GroupFeatureCache::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

}  // namespace cashash
