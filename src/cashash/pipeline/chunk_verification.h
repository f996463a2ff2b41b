// What travels between the matching pipeline's stages, and the
// verification of matched chunks in one call of the batch verifier. Internal
// to the pipeline (matching_pipeline.cc); apart so that each file holds one
// job: this one the chunks, that one the stages and their threads.
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <unordered_map>
#include <vector>

#include "cashash/pipeline/matching_pipeline.h"

namespace cashash {
namespace pipeline_internal {

using Clock = std::chrono::steady_clock;
using FeaturesPtr = std::shared_ptr<const ImageFeatures>;

// An image's descriptors and keypoints, sharing ownership of its features.
std::shared_ptr<const FeatureDescriptors> DescriptorsOf(const FeaturesPtr& features);
std::shared_ptr<const Keypoints> KeypointsOf(const FeaturesPtr& features);

// What travels from the matching stage to the verification stage.
struct MatchedChunk {
  size_t index = 0;  // position in the run's chunks: the writer's order
  // Made for the run when it was matched (PairChunkSource::Chunk); lives
  // until it is written.
  std::shared_ptr<const PairChunk> chunk;
  std::unordered_map<image_t, FeaturesPtr> features;
  std::vector<FeatureMatches> matches;
  // The exact rematch left to the verification thread (ExactRematchStage):
  // done there before verifying.
  PendingRematch rematch;
  Clock::time_point started;
};

struct VerifiedChunk {
  size_t index = 0;
  std::shared_ptr<const PairChunk> chunk;
  std::shared_ptr<std::vector<PairResult>> results = std::make_shared<std::vector<PairResult>>();
  Clock::time_point started;
  // For the trace: the chunk's rematch on the verification thread, if it
  // had one, and when its verifier call started.
  bool rematched = false;
  Clock::time_point rematch_started, rematch_ended, verify_started;
};

// Completes the exact rematch left to the verification thread for `item`,
// if any (`rematch` may be null where the run has none); returns whether
// there was one.
bool CompleteRematch(ExactRematchStage* rematch, MatchedChunk* item);

// The verification of matched chunks in one call of the verifier: for each
// chunk the rematch left to it first (`rematch` may be null), then results in the chunk's pair order, geometries left undefined when
// verification is skipped. One call for several chunks because a GPU call
// lasts as long as its slowest pair: chunks that wait together share that
// tail instead of paying it in turn. Releases the chunks' features.
std::vector<VerifiedChunk> VerifyChunks(const PipelineOptions& options, FeatureSource* source,
                                        ExactRematchStage* rematch, std::vector<MatchedChunk>* items,
                                        BatchVerifier* verifier);

}  // namespace pipeline_internal
}  // namespace cashash
