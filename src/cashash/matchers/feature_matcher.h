// The interface every matching backend (CPU cascade, CPU brute force, GPU
// cascade, GPU brute force) implements. The pipeline adds the images of the
// current block once, so per-image work (hash codes, bucket tables, device
// uploads) is done once per image and reused for all of its pairs.
#pragma once

#include <array>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "cashash/base/types.h"
#include "cashash/matching/matching_options.h"
#include "cashash/matching/mean_descriptor.h"

namespace cashash {

// One pair of guided matching (Ga-CasHash stage 2, guided_matching.h): its
// fundamental matrix and the keypoint pixels of both images. The pointers
// must stay valid during the call.
struct GuidedPair {
  ImagePair pair;
  std::array<double, 9> F{};  // row-major, x2^T F x1 = 0 (pixels of first, second image)
  // x, y of feature i at [2 i], [2 i + 1]; at least the rows added.
  const std::vector<float>* points1 = nullptr;
  const std::vector<float>* points2 = nullptr;
};

// Work on a chunk's matches that a matcher leaves for later, so that its
// caller can match the next chunk meanwhile (the exact rematch on the GPU,
// exact_rematch_feature_matcher.h). Complete may run on another thread than
// the matcher's, concurrently with its next calls.
class DeferredMatching {
 public:
  virtual ~DeferredMatching() = default;
  // The descriptors of an image of the chunk, still held by the caller.
  using DescriptorLookup = std::function<std::shared_ptr<const FeatureDescriptors>(image_t)>;
  // Replaces the matches of the pairs it was left for; `matches` are the
  // chunk's, in its pair order.
  virtual void Complete(const DescriptorLookup& descriptors, std::vector<FeatureMatches>* matches) = 0;
};

// Exact matches of some pairs, taken now from what a matcher holds and
// computed later by Run, on any thread, while the matcher goes on adding,
// removing and matching images (FeatureMatcher::DeferExactMatching).
class ExactMatchingTicket {
 public:
  virtual ~ExactMatchingTicket() = default;
  // The pairs' exact matches, in the order they were given; once.
  virtual std::vector<FeatureMatches> Run() = 0;
};

// A chunk's matches, and what is left to complete them (null: nothing).
struct ChunkMatches {
  std::vector<FeatureMatches> matches;
  std::unique_ptr<DeferredMatching> deferred;
};

class FeatureMatcher {
 public:
  virtual ~FeatureMatcher() = default;

  // Makes an image available to MatchPairs. Descriptors beyond
  // max_num_matches rows are ignored. Adding an id twice replaces it.
  virtual void AddImage(image_t image_id, const FeatureDescriptors& descriptors) = 0;
  // AddImage for a caller that shares ownership of the descriptors (the
  // pipeline). A matcher that must keep a host copy (the fallback to the
  // CPU, to rebuild from) keeps this handle instead: the copy was most of
  // the time the matching thread spent adding images (H200, 5,000 images:
  // 3.4-4.8 s of 5.0-6.8 s) and a second host copy of every image. The
  // default calls AddImage.
  virtual void AddSharedImage(image_t image_id, std::shared_ptr<const FeatureDescriptors> descriptors) {
    AddImage(image_id, *descriptors);
  }
  // Frees what AddImage holds for this image.
  virtual void RemoveImage(image_t image_id) = 0;
  // Matches each pair (both images added before); result i belongs to pair i
  // and indexes (first image, second image) of that pair.
  virtual std::vector<FeatureMatches> MatchPairs(const std::vector<ImagePair>& pairs) = 0;
  // MatchPairs for a caller that can complete part of the work later, on
  // another thread (the pipeline: before verifying the chunk). The default
  // leaves nothing; wrappers forward it.
  virtual ChunkMatches MatchPairsDeferred(const std::vector<ImagePair>& pairs) {
    return ChunkMatches{MatchPairs(pairs), nullptr};
  }
  // A short name for logs: "cpu-cascade", "gpu-bruteforce", ...
  virtual std::string Name() const = 0;

  // Whether MatchPairsGuided is implemented (the cascade backends).
  virtual bool SupportsEpipolarGuidance() const { return false; }
  // MatchPairs with each query's candidates restricted to the band of
  // max_distance pixels around its epipolar line (cascade_matcher.h,
  // EpipolarGuidance). Throws std::logic_error where not supported.
  virtual std::vector<FeatureMatches> MatchPairsGuided(const std::vector<GuidedPair>& pairs, double max_distance);

  // Whether MatchPairsExact is implemented (the cascade backends, which keep
  // each image's descriptors anyway).
  virtual bool SupportsExactMatching() const { return false; }
  // Exact (brute-force) matches of each pair from the images already added:
  // the same matches a brute-force backend returns, without adding the
  // images to one (exact_rematch_feature_matcher.h). Throws
  // std::logic_error where not supported.
  virtual std::vector<FeatureMatches> MatchPairsExact(const std::vector<ImagePair>& pairs);
  // MatchPairsExact for later and on another thread: the ticket keeps what
  // it needs of the pairs' images (the GPU cascade: their descriptors on
  // the device, which it then neither uploads again nor frees early).
  // nullptr where not supported (the default); the caller then matches
  // some other way.
  virtual std::unique_ptr<ExactMatchingTicket> DeferExactMatching(const std::vector<ImagePair>& pairs) {
    (void)pairs;
    return nullptr;
  }
};

// CPU backends (multi-threaded over pairs). MatcherType::kAuto is refused
// (std::invalid_argument): it is decided first (ChooseAutoMatcher,
// matcher_choice.h), as are the GPU backends'.
std::unique_ptr<FeatureMatcher> CreateCpuFeatureMatcher(const SiftMatchingOptions& sift_options,
                                                        const CasHashOptions& cashash_options,
                                                        const MeanDescriptor& mean);

}  // namespace cashash
