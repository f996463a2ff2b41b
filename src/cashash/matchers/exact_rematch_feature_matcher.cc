#include "cashash/matchers/exact_rematch_feature_matcher.h"

#include <chrono>
#include <stdexcept>
#include <utility>

#include "cashash/base/device_memory_error.h"
#include "cashash/base/pair_id.h"

namespace cashash {

std::vector<FeatureMatches> FeatureMatcher::MatchPairsExact(const std::vector<ImagePair>&) {
  throw std::logic_error("the " + Name() + " matcher does not match from its own descriptors exactly");
}

namespace {

int64_t MicrosecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now() - start).count();
}

// The exact matching of a chunk's pairs that reached the threshold: by the
// cascade's ticket (from the descriptors it holds) where it gives one, else
// on a pooled brute-force matcher fed with the chunk's descriptors.
class DeferredExactRematch : public DeferredMatching {
 public:
  DeferredExactRematch(std::vector<size_t> indices, std::vector<ImagePair> pairs,
                       std::unique_ptr<ExactMatchingTicket> ticket, std::shared_ptr<ExactMatcherPool> pool,
                       std::shared_ptr<ExactRematchCounts> counts)
      : indices_(std::move(indices)),
        pairs_(std::move(pairs)),
        ticket_(std::move(ticket)),
        pool_(std::move(pool)),
        counts_(std::move(counts)) {}

  void Complete(const DescriptorLookup& descriptors, std::vector<FeatureMatches>* matches) override {
    const auto start = std::chrono::steady_clock::now();
    std::vector<FeatureMatches> exact_matches;
    bool matched = false;
    if (ticket_) {
      try {
        exact_matches = ticket_->Run();
        matched = true;
      } catch (const DeviceMemoryError&) {
        ++counts_->tickets_without_memory;
      }
      ticket_.reset();  // lets go of the images now
    }
    if (!matched) {
      const std::vector<image_t> images = ImagesOfPairs(pairs_);
      // On an error the matcher, which may still hold images, is dropped
      // instead of going back to the pool.
      std::unique_ptr<FeatureMatcher> exact = pool_->Acquire();
      for (const image_t image_id : images) exact->AddSharedImage(image_id, descriptors(image_id));
      exact_matches = exact->MatchPairs(pairs_);
      for (const image_t image_id : images) exact->RemoveImage(image_id);
      pool_->Release(std::move(exact));
    }
    if (exact_matches.size() != pairs_.size()) throw std::logic_error("deferred rematch: wrong number of results");
    for (size_t k = 0; k < indices_.size(); ++k) matches->at(indices_[k]) = std::move(exact_matches[k]);
    counts_->rematched += pairs_.size();
    counts_->exact_us += MicrosecondsSince(start);
  }

 private:
  std::vector<size_t> indices_;
  std::vector<ImagePair> pairs_;
  std::unique_ptr<ExactMatchingTicket> ticket_;
  std::shared_ptr<ExactMatcherPool> pool_;
  std::shared_ptr<ExactRematchCounts> counts_;
};

}  // namespace

ExactRematchFeatureMatcher::ExactRematchFeatureMatcher(std::unique_ptr<FeatureMatcher> cascade, size_t min_matches,
                                                       std::shared_ptr<ExactRematchCounts> counts,
                                                       std::shared_ptr<ExactMatcherPool> pool, size_t max_matches)
    : cascade_(std::move(cascade)),
      min_matches_(min_matches),
      max_matches_(max_matches),
      counts_(counts ? std::move(counts) : std::make_shared<ExactRematchCounts>()),
      pool_(std::move(pool)) {
  if (!cascade_) throw std::invalid_argument("ExactRematchFeatureMatcher needs a matcher");
  if (!cascade_->SupportsExactMatching()) {
    throw std::invalid_argument("ExactRematchFeatureMatcher: the " + cascade_->Name() +
                                " matcher cannot match exactly from its own descriptors");
  }
  if (min_matches_ == 0) throw std::invalid_argument("ExactRematchFeatureMatcher needs min_matches > 0");
  if (max_matches_ != 0 && max_matches_ <= min_matches_) {
    throw std::invalid_argument("ExactRematchFeatureMatcher needs max_matches 0 or above min_matches");
  }
}

void ExactRematchFeatureMatcher::AddImage(image_t image_id, const FeatureDescriptors& descriptors) {
  cascade_->AddImage(image_id, descriptors);
}

void ExactRematchFeatureMatcher::AddSharedImage(image_t image_id,
                                                std::shared_ptr<const FeatureDescriptors> descriptors) {
  cascade_->AddSharedImage(image_id, std::move(descriptors));
}

void ExactRematchFeatureMatcher::RemoveImage(image_t image_id) { cascade_->RemoveImage(image_id); }

std::vector<size_t> ExactRematchFeatureMatcher::PairsToRematch(const std::vector<FeatureMatches>& results) const {
  std::vector<size_t> again;
  for (size_t i = 0; i < results.size(); ++i) {
    const size_t found = results[i].size();
    if (found >= min_matches_ && (max_matches_ == 0 || found < max_matches_)) again.push_back(i);
  }
  return again;
}

ChunkMatches ExactRematchFeatureMatcher::MatchPairsDeferred(const std::vector<ImagePair>& pairs) {
  if (!pool_) return ChunkMatches{MatchPairs(pairs), nullptr};
  ChunkMatches out;
  out.matches = cascade_->MatchPairs(pairs);
  counts_->pairs += pairs.size();
  std::vector<size_t> again = PairsToRematch(out.matches);
  if (again.empty()) return out;
  std::vector<ImagePair> subset;
  subset.reserve(again.size());
  for (const size_t i : again) subset.push_back(pairs[i]);
  // A ticket saves uploading the images again: that upload, beside the next
  // chunk's, made adding images 0.07 s slower at 300 images.
  std::unique_ptr<ExactMatchingTicket> ticket = cascade_->DeferExactMatching(subset);
  out.deferred = std::make_unique<DeferredExactRematch>(std::move(again), std::move(subset), std::move(ticket), pool_,
                                                        counts_);
  return out;
}

std::vector<FeatureMatches> ExactRematchFeatureMatcher::MatchPairs(const std::vector<ImagePair>& pairs) {
  std::vector<FeatureMatches> results = cascade_->MatchPairs(pairs);
  const std::vector<size_t> again = PairsToRematch(results);
  counts_->pairs += pairs.size();
  if (again.empty()) return results;
  const auto start = std::chrono::steady_clock::now();
  std::vector<ImagePair> subset;
  subset.reserve(again.size());
  for (const size_t i : again) subset.push_back(pairs[i]);
  std::vector<FeatureMatches> exact = cascade_->MatchPairsExact(subset);
  for (size_t k = 0; k < again.size(); ++k) results[again[k]] = std::move(exact[k]);
  counts_->rematched += again.size();
  counts_->exact_us += MicrosecondsSince(start);
  return results;
}

std::string ExactRematchFeatureMatcher::Name() const { return cascade_->Name() + "+exact-rematch"; }

bool ExactRematchFeatureMatcher::SupportsEpipolarGuidance() const { return cascade_->SupportsEpipolarGuidance(); }

std::vector<FeatureMatches> ExactRematchFeatureMatcher::MatchPairsGuided(const std::vector<GuidedPair>& pairs,
                                                                         double max_distance) {
  return cascade_->MatchPairsGuided(pairs, max_distance);
}

std::vector<FeatureMatches> ExactRematchFeatureMatcher::MatchPairsExact(const std::vector<ImagePair>& pairs) {
  return cascade_->MatchPairsExact(pairs);
}

}  // namespace cashash
