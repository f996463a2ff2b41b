#include "cashash/pipeline/exact_rematch_stage.h"

#include <chrono>
#include <stdexcept>
#include <utility>

#include "cashash/base/device_memory_error.h"
#include "cashash/base/pair_id.h"

namespace cashash {
namespace {

int64_t MicrosecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

const char* RematchPlaceName(RematchPlace place) {
  switch (place) {
    case RematchPlace::kNowhere:
      return "nowhere";
    case RematchPlace::kMatchingThread:
      return "matching thread";
    case RematchPlace::kVerificationThread:
      return "verification thread";
  }
  return "?";
}

bool ExactRematchPolicy::Selects(size_t cascade_matches) const {
  return enabled() && cascade_matches >= min_matches && (max_matches == 0 || cascade_matches < max_matches);
}

std::string ExactRematchPolicy::Check() const {
  if (!enabled()) return "";
  if (min_matches == 0) return "the exact rematch needs min_matches > 0";
  if (max_matches != 0 && max_matches <= min_matches) {
    return "the exact rematch needs max_matches 0 or above min_matches";
  }
  return "";
}

ExactRematchStage::ExactRematchStage(const ExactRematchPolicy& policy, MatchingBackend* backend,
                                     std::shared_ptr<ExactMatcherPool> pool)
    : policy_(policy), backend_(backend), pool_(std::move(pool)) {
  const std::string error = policy_.Check();
  if (!error.empty()) throw std::invalid_argument(error);
  if (policy_.enabled() && backend_ == nullptr) throw std::invalid_argument("the exact rematch needs a backend");
}

PendingRematch ExactRematchStage::AfterMatching(const std::vector<ImagePair>& pairs,
                                                std::vector<FeatureMatches>* matches) {
  PendingRematch pending;
  if (!policy_.enabled()) return pending;
  counts_.pairs += pairs.size();
  for (size_t i = 0; i < matches->size(); ++i) {
    if (!policy_.Selects((*matches)[i].size())) continue;
    pending.indices.push_back(i);
    pending.pairs.push_back(pairs[i]);
  }
  if (pending.empty()) return pending;
  if (policy_.where == RematchPlace::kVerificationThread) {
    // Held, not uploaded again: that upload, beside the next chunk's, made
    // adding images slower.
    pending.held = backend_->HoldForExact(pending.pairs);
    return pending;
  }
  const auto start = std::chrono::steady_clock::now();
  std::vector<FeatureMatches> exact = backend_->MatchExact(pending.pairs);
  if (exact.size() != pending.pairs.size()) throw std::logic_error("exact rematch: wrong number of results");
  for (size_t k = 0; k < pending.indices.size(); ++k) (*matches)[pending.indices[k]] = std::move(exact[k]);
  counts_.rematched += pending.pairs.size();
  counts_.exact_us += MicrosecondsSince(start);
  return PendingRematch();
}

std::vector<FeatureMatches> ExactRematchStage::MatchWithPool(const std::vector<ImagePair>& pairs,
                                                             const DescriptorLookup& descriptors) {
  const std::vector<image_t> images = ImagesOfPairs(pairs);
  // On an error the matcher, which may still hold images, is dropped
  // instead of going back to the pool.
  std::unique_ptr<FeatureMatcher> exact = pool_->Acquire();
  for (const image_t image_id : images) exact->AddImage(MatcherImage{image_id, nullptr, descriptors(image_id)});
  std::vector<FeatureMatches> matches = exact->Match(pairs);
  for (const image_t image_id : images) exact->RemoveImage(image_id);
  pool_->Release(std::move(exact));
  return matches;
}

void ExactRematchStage::Complete(PendingRematch* pending, const DescriptorLookup& descriptors,
                                 std::vector<FeatureMatches>* matches) {
  if (pending->empty()) return;
  const auto start = std::chrono::steady_clock::now();
  std::vector<FeatureMatches> exact;
  bool matched = false;
  if (pending->held) {
    try {
      exact = pending->held->MatchExact(pending->pairs);
      matched = true;
    } catch (const DeviceMemoryError&) {
      if (!pool_) throw;
      ++counts_.held_without_memory;
    }
    pending->held.reset();  // lets go of the images now
  }
  if (!matched) {
    if (!pool_) throw std::logic_error("exact rematch: nothing holds the pairs' images");
    exact = MatchWithPool(pending->pairs, descriptors);
  }
  if (exact.size() != pending->pairs.size()) throw std::logic_error("exact rematch: wrong number of results");
  for (size_t k = 0; k < pending->indices.size(); ++k) matches->at(pending->indices[k]) = std::move(exact[k]);
  counts_.rematched += pending->pairs.size();
  counts_.exact_us += MicrosecondsSince(start);
  *pending = PendingRematch();
}

}  // namespace cashash
