// Exact (brute-force) matching from the images a backend already holds, and
// the backend type that offers it beside FeatureMatcher.
//
// The cascade backends keep each image's descriptors anyway (the GPU on the
// device), so the exact rematch (pipeline/exact_rematch_stage.h) and guided
// matching's stage 2 (guided_matching.h) match exactly from them instead of
// adding the images to a second, brute-force matcher: the same matches a
// brute-force backend returns, without a second upload.
#pragma once

#include <memory>
#include <vector>

#include "cashash/matchers/feature_matcher.h"

namespace cashash {

class ExactMatcher {
 public:
  virtual ~ExactMatcher() = default;
  // Exact matches of each pair of images it holds, as a brute-force backend
  // returns them; result i belongs to pair i.
  virtual std::vector<FeatureMatches> MatchExact(const std::vector<ImagePair>& pairs) = 0;
};

// A backend (CPU or GPU, cascade or brute force) and what its combinators
// (several devices: split_feature_matcher.h; the fallback to the CPU:
// fallback_feature_matcher.h) are: a FeatureMatcher that also matches
// exactly from its images. Every backend can: brute force's Match is exact
// already.
class MatchingBackend : public FeatureMatcher, public ExactMatcher {
 public:
  // An exact matcher of `pairs` (a subset of the added images) that keeps
  // what it needs of their images as they are now (the GPU cascade: their
  // blocks of device memory, neither uploaded again nor freed early; the
  // CPU: the images' shared data), so that it can run on another thread,
  // later, while this backend goes on adding, removing and matching images.
  // Only the held pairs may be asked of it. Called on the thread that adds
  // images.
  virtual std::unique_ptr<ExactMatcher> HoldForExact(const std::vector<ImagePair>& pairs) = 0;

 protected:
  using FeatureMatcher::FeatureMatcher;
};

// CPU backends (multi-threaded over pairs). Options with a value still
// chosen for the run (matcher auto, tau 0, rematch threshold -1) are refused
// with std::invalid_argument naming it (CasHashOptions::CheckDecided): a
// run decides them first (ResolveRun), as for the GPU backends.
std::unique_ptr<MatchingBackend> CreateCpuFeatureMatcher(const SiftMatchingOptions& sift_options,
                                                         const CasHashOptions& cashash_options,
                                                         const MeanDescriptor& mean);

}  // namespace cashash
