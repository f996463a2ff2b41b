#include "cashash/pipeline/chunk_verification.h"

#include <stdexcept>
#include <utility>

#include "cashash/base/pair_id.h"
#include "cashash/base/parallel_for.h"

namespace cashash {
namespace pipeline_internal {

std::shared_ptr<const FeatureDescriptors> DescriptorsOf(const FeaturesPtr& features) {
  return std::shared_ptr<const FeatureDescriptors>(features, &features->descriptors);
}

std::shared_ptr<const Keypoints> KeypointsOf(const FeaturesPtr& features) {
  return std::shared_ptr<const Keypoints>(features, &features->keypoints);
}

bool CompleteRematch(ExactRematchStage* rematch, MatchedChunk* item) {
  if (item->rematch.empty()) return false;
  if (rematch == nullptr) throw std::logic_error("a chunk's exact rematch was left without its stage");
  rematch->Complete(
      &item->rematch, [&](image_t image_id) { return DescriptorsOf(item->features.at(image_id)); }, &item->matches);
  return true;
}

std::vector<VerifiedChunk> VerifyChunks(const PipelineOptions& options, FeatureSource* source,
                                        ExactRematchStage* rematch, std::vector<MatchedChunk>* items,
                                        BatchVerifier* verifier) {
  std::vector<VerifiedChunk> out(items->size());
  for (size_t c = 0; c < items->size(); ++c) {
    MatchedChunk& item = (*items)[c];
    out[c].index = item.index;
    out[c].chunk = item.chunk;
    out[c].started = item.started;
    out[c].rematch_started = Clock::now();
    out[c].rematched = CompleteRematch(rematch, &item);
    out[c].rematch_ended = Clock::now();
    const std::vector<ImagePair>& pairs = item.chunk->pairs;
    std::vector<PairResult>& results = *out[c].results;
    results.resize(pairs.size());
    for (size_t k = 0; k < pairs.size(); ++k) {
      results[k].pair = pairs[k];
      results[k].matches = std::move(item.matches[k]);
    }
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

}  // namespace pipeline_internal
}  // namespace cashash
