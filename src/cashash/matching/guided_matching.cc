#include "cashash/matching/guided_matching.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include "cashash/pipeline/batch_verifier.h"
#include "cashash/matching/epipolar_band.h"
#include "cashash/base/parallel_for.h"

namespace cashash {

std::string GuidedMatchingOptions::Check() const {
  if (!(top_scale_fraction > 0 && top_scale_fraction <= 1)) {
    return "--GuidedMatching.top_scale_fraction must be in (0, 1]";
  }
  if (min_num_matches < 8) {
    return "--GuidedMatching.min_num_matches must be >= 8 (F needs 7 matches and a check)";
  }
  if (!(min_inlier_ratio >= 0 && min_inlier_ratio <= 1)) {
    return "--GuidedMatching.min_inlier_ratio must be in [0, 1]";
  }
  if (fallback_min_num_matches < 1 || fallback_min_num_matches > min_num_matches) {
    return "--GuidedMatching.fallback_min_num_matches must be in [1, --GuidedMatching.min_num_matches]";
  }
  if (!(max_epipolar_distance >= 0) || !std::isfinite(max_epipolar_distance)) {
    return "--GuidedMatching.max_epipolar_distance must be a number of pixels >= 0 (0: the default of the method)";
  }
  return "";
}

float KeypointScale(const Keypoint& k) { return std::sqrt(std::abs(k.a11 * k.a22 - k.a12 * k.a21)); }

std::vector<uint32_t> SelectTopScaleFeatures(const Keypoints& keypoints, size_t num_rows, double fraction) {
  const size_t n = std::min(num_rows, keypoints.size());
  if (n == 0) return {};
  // ceil, without 0.2 * 10 becoming 2.0000000000000004 -> 3.
  size_t count = static_cast<size_t>(std::ceil(fraction * static_cast<double>(n) - 1e-9));
  count = std::clamp<size_t>(count, 1, n);
  std::vector<uint32_t> rows(n);
  for (size_t i = 0; i < n; ++i) rows[i] = static_cast<uint32_t>(i);
  std::vector<float> scales(n);
  for (size_t i = 0; i < n; ++i) scales[i] = KeypointScale(keypoints[i]);
  auto larger = [&](uint32_t a, uint32_t b) { return scales[a] != scales[b] ? scales[a] > scales[b] : a < b; };
  std::nth_element(rows.begin(), rows.begin() + (count - 1), rows.end(), larger);
  rows.resize(count);
  std::sort(rows.begin(), rows.end());
  return rows;
}

std::vector<float> InterleavedPositions(const Keypoints& keypoints, size_t num_rows) {
  const size_t n = std::min(num_rows, keypoints.size());
  std::vector<float> xy(2 * n);
  for (size_t i = 0; i < n; ++i) {
    xy[2 * i] = keypoints[i].x;
    xy[2 * i + 1] = keypoints[i].y;
  }
  return xy;
}

namespace {

class CpuFundamentalEstimator : public BatchFundamentalEstimator {
 public:
  CpuFundamentalEstimator(const TwoViewGeometryOptions& options, int num_threads)
      : options_(options), num_threads_(num_threads) {}
  std::string Name() const override { return "cpu"; }
  std::vector<TwoViewModelEstimate> Estimate(const std::vector<const TwoViewPoints*>& pairs,
                                             const std::vector<uint64_t>& seeds) override {
    std::vector<TwoViewModelEstimate> out(pairs.size());
    ParallelFor(pairs.size(), num_threads_, [&](size_t k) {
      TwoViewGeometryOptions options = options_;
      options.random_seed = seeds[k];
      out[k] = EstimateFundamental(*pairs[k], options);
    });
    return out;
  }

 private:
  const TwoViewGeometryOptions options_;
  const int num_threads_;
};

using Clock = std::chrono::steady_clock;
double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

}  // namespace

std::unique_ptr<BatchFundamentalEstimator> CreateCpuFundamentalEstimator(const TwoViewGeometryOptions& options,
                                                                         int num_threads) {
  return std::make_unique<CpuFundamentalEstimator>(options, num_threads);
}

GuidedStage1Outcome DecideGuidedStage1(size_t num_matches, const TwoViewModelEstimate* F,
                                       const GuidedMatchingOptions& options) {
  if (num_matches < static_cast<size_t>(options.min_num_matches)) {
    return options.unguided_fallback && num_matches >= static_cast<size_t>(options.fallback_min_num_matches)
               ? GuidedStage1Outcome::kNoModel
               : GuidedStage1Outcome::kTooFewMatches;
  }
  if (F == nullptr || !F->success) return GuidedStage1Outcome::kFewInliers;
  // A tolerance so that 2/3 of 24 matches (15.999...) asks for 16.
  const double needed = options.min_inlier_ratio * static_cast<double>(num_matches) - 1e-9;
  return static_cast<double>(F->num_inliers) >= needed ? GuidedStage1Outcome::kGuided
                                                        : GuidedStage1Outcome::kFewInliers;
}

FeatureMatches KeepMatchesInEpipolarBand(const FeatureMatches& matches, const double* F, const std::vector<float>& xy1,
                                         const std::vector<float>& xy2, double max_distance) {
  FeatureMatches kept;
  kept.reserve(matches.size());
  for (const FeatureMatch& m : matches) {
    const size_t i = 2 * static_cast<size_t>(m.point2D_idx1), j = 2 * static_cast<size_t>(m.point2D_idx2);
    if (i + 1 >= xy1.size() || j + 1 >= xy2.size()) {
      throw std::out_of_range("KeepMatchesInEpipolarBand: a match indexes a feature without a position");
    }
    if (LineInSecondImage(F, xy1[i], xy1[i + 1]).Contains(xy2[j], xy2[j + 1], max_distance) &&
        LineInFirstImage(F, xy2[j], xy2[j + 1]).Contains(xy1[i], xy1[i + 1], max_distance)) {
      kept.push_back(m);
    }
  }
  return kept;
}

namespace {

MatcherTraits GuidedTraits(const MatchingBackend* full, const BatchFundamentalEstimator* fundamental) {
  MatcherTraits traits;
  traits.name = "guided(" + (full ? full->Name() : std::string("?")) + ", F on " +
                (fundamental ? fundamental->Name() : std::string("?")) + ")";
  traits.uses_keypoints = true;
  return traits;
}

}  // namespace

GuidedFeatureMatcher::GuidedFeatureMatcher(std::unique_ptr<MatchingBackend> full,
                                           std::unique_ptr<FeatureMatcher> top_scale,
                                           std::unique_ptr<BatchFundamentalEstimator> fundamental,
                                           const GuidedMatchingOptions& options, int max_num_matches,
                                           uint64_t random_seed, int num_threads)
    : FeatureMatcher(GuidedTraits(full.get(), fundamental.get())),
      full_(std::move(full)),
      top_scale_(std::move(top_scale)),
      fundamental_(std::move(fundamental)),
      options_(options),
      max_num_matches_(static_cast<size_t>(std::max(0, max_num_matches))),
      random_seed_(random_seed),
      num_threads_(num_threads) {
  const std::string error = options.Check();
  if (!error.empty()) throw std::invalid_argument(error);
  if (!full_ || !top_scale_ || !fundamental_) {
    throw std::invalid_argument("GuidedFeatureMatcher: a matcher or the F estimator is missing");
  }
  if (options_.restrict_search_to_band && !full_->traits().epipolar_guidance) {
    throw std::invalid_argument("guided matching needs the cascade matcher (--CasHash.matcher cascade), not " +
                                full_->Name());
  }
  stats_.searched_in_band = options_.restrict_search_to_band;
}

void GuidedFeatureMatcher::AddImage(const Image& added) {
  if (!added.keypoints) {
    throw std::logic_error("guided matching: image " + std::to_string(added.id) + " was added without keypoints");
  }
  const FeatureDescriptors& descriptors = *added.descriptors;
  const Keypoints& keypoints = *added.keypoints;
  const size_t n = std::min({descriptors.rows(), max_num_matches_, keypoints.size()});
  GuidedImage image;
  image.top_scale_rows = SelectTopScaleFeatures(keypoints, n, options_.top_scale_fraction);
  image.positions.resize(n);
  for (size_t i = 0; i < n; ++i) image.positions[i] = Eigen::Vector2d(keypoints[i].x, keypoints[i].y);
  image.interleaved = InterleavedPositions(keypoints, n);
  auto subset = std::make_shared<FeatureDescriptors>();
  subset->data.resize(image.top_scale_rows.size() * kDescriptorDim);
  for (size_t r = 0; r < image.top_scale_rows.size(); ++r) {
    std::copy_n(descriptors.row(image.top_scale_rows[r]), kDescriptorDim, subset->data.data() + r * kDescriptorDim);
  }
  const Clock::time_point t0 = Clock::now();
  top_scale_->AddImage(MatcherImage{added.id, nullptr, std::move(subset)});
  stats_.seconds_stage1 += SecondsSince(t0);
  // The full matcher needs the keypoints only to search within the bands.
  MatcherImage full{added.id, options_.restrict_search_to_band ? added.keypoints : nullptr, added.descriptors};
  if (n < descriptors.rows()) {
    // Only the rows with a position are matched (a database keeps as many
    // keypoints as descriptors; this guards against one that does not).
    auto head = std::make_shared<FeatureDescriptors>();
    head->data.assign(descriptors.data.begin(), descriptors.data.begin() + n * kDescriptorDim);
    full.descriptors = std::move(head);
  }
  full_->AddImage(full);
  images_[added.id] = std::move(image);
}

void GuidedFeatureMatcher::RemoveImage(image_t image_id) {
  images_.erase(image_id);
  top_scale_->RemoveImage(image_id);
  full_->RemoveImage(image_id);
}

const GuidedFeatureMatcher::GuidedImage& GuidedFeatureMatcher::Find(image_t image_id) const {
  const auto it = images_.find(image_id);
  if (it == images_.end()) {
    throw std::out_of_range("Match: image " + std::to_string(image_id) + " was not added to the guided matcher");
  }
  return it->second;
}

// One function because the chunk's stages (stage 1, batched F, stage 2,
// fallback) hand per-pair index maps (candidates, guided_index,
// fallback_index) and the stats and timings from one stage to the next.
std::vector<FeatureMatches> GuidedFeatureMatcher::Match(const std::vector<ImagePair>& pairs,
                                                        const std::vector<EpipolarGuide>& guides) {
  if (!guides.empty()) throw std::logic_error("the guided matcher makes its own epipolar guides");
  std::vector<FeatureMatches> results(pairs.size());
  last_outcomes_.assign(pairs.size(), GuidedStage1Outcome::kTooFewMatches);
  stats_.pairs += pairs.size();

  // Stage 1: the top-scale subsets, rows mapped back to the images' rows.
  Clock::time_point t0 = Clock::now();
  std::vector<FeatureMatches> stage1 = top_scale_->Match(pairs);
  std::vector<size_t> candidates;
  for (size_t k = 0; k < pairs.size(); ++k) {
    const std::vector<uint32_t>& rows1 = Find(pairs[k].first).top_scale_rows;
    const std::vector<uint32_t>& rows2 = Find(pairs[k].second).top_scale_rows;
    for (FeatureMatch& m : stage1[k]) {
      m.point2D_idx1 = rows1.at(m.point2D_idx1);
      m.point2D_idx2 = rows2.at(m.point2D_idx2);
    }
    stats_.stage1_matches += stage1[k].size();
    if (stage1[k].size() >= static_cast<size_t>(options_.min_num_matches)) candidates.push_back(k);
  }
  stats_.seconds_stage1 += SecondsSince(t0);

  // F of the pairs with enough stage-1 matches, all at once.
  t0 = Clock::now();
  std::vector<TwoViewPoints> points(candidates.size());
  ParallelFor(candidates.size(), num_threads_, [&](size_t c) {
    const size_t k = candidates[c];
    points[c] = PrepareTwoViewPoints(Find(pairs[k].first).positions, Find(pairs[k].second).positions, stage1[k]);
  });
  std::vector<const TwoViewPoints*> point_ptrs(candidates.size());
  std::vector<uint64_t> seeds(candidates.size());
  for (size_t c = 0; c < candidates.size(); ++c) {
    point_ptrs[c] = &points[c];
    seeds[c] = PairRandomSeed(random_seed_, pairs[candidates[c]]);
  }
  std::vector<TwoViewModelEstimate> fundamentals;
  if (!candidates.empty()) fundamentals = fundamental_->Estimate(point_ptrs, seeds);
  stats_.pairs_enough_matches += candidates.size();
  std::vector<ImagePair> guided;
  std::vector<EpipolarGuide> guides_of_pairs;
  std::vector<size_t> guided_index;
  std::vector<ImagePair> fallback;
  std::vector<size_t> fallback_index;
  size_t next_candidate = 0;
  for (size_t k = 0; k < pairs.size(); ++k) {
    const TwoViewModelEstimate* F = nullptr;
    if (next_candidate < candidates.size() && candidates[next_candidate] == k) F = &fundamentals[next_candidate++];
    last_outcomes_[k] = DecideGuidedStage1(stage1[k].size(), F, options_);
    if (last_outcomes_[k] == GuidedStage1Outcome::kNoModel) ++stats_.pairs_weak;  // only with the fallback
    if (options_.unguided_fallback && (last_outcomes_[k] == GuidedStage1Outcome::kFewInliers ||
                                       last_outcomes_[k] == GuidedStage1Outcome::kNoModel)) {
      fallback.push_back(pairs[k]);
      fallback_index.push_back(k);
    }
    if (last_outcomes_[k] != GuidedStage1Outcome::kGuided) continue;
    EpipolarGuide g;
    for (int r = 0; r < 3; ++r)
      for (int col = 0; col < 3; ++col) g.F[3 * r + col] = F->model(r, col);
    g.max_distance = options_.EpipolarDistance();
    guided.push_back(pairs[k]);
    guides_of_pairs.push_back(g);
    guided_index.push_back(k);
  }
  stats_.seconds_fundamental += SecondsSince(t0);
  stats_.pairs_guided += guided.size();

  // Stage 2: all features; the band searched (the paper) or applied to the
  // exact matches.
  t0 = Clock::now();
  if (!guided.empty()) {
    std::vector<FeatureMatches> stage2;
    if (options_.restrict_search_to_band) {
      stage2 = full_->Match(guided, guides_of_pairs);
    } else {
      stage2 = full_->MatchExact(guided);
      for (size_t g = 0; g < guided.size(); ++g) stats_.stage2_exact_matches += stage2[g].size();
      ParallelFor(guided.size(), num_threads_, [&](size_t g) {
        stage2[g] = KeepMatchesInEpipolarBand(stage2[g], guides_of_pairs[g].F.data(), Find(guided[g].first).interleaved,
                                              Find(guided[g].second).interleaved, options_.EpipolarDistance());
      });
    }
    for (size_t g = 0; g < guided.size(); ++g) {
      stats_.stage2_matches += stage2[g].size();
      results[guided_index[g]] = std::move(stage2[g]);
    }
  }
  stats_.seconds_stage2 += SecondsSince(t0);

  // Pairs stage 1 could not guide, exactly and without the band
  // (unguided_fallback; the cascade with restrict_search_to_band, as the
  // paper's method has no exact matching).
  t0 = Clock::now();
  if (!fallback.empty()) {
    std::vector<FeatureMatches> unguided =
        options_.restrict_search_to_band ? full_->Match(fallback) : full_->MatchExact(fallback);
    for (size_t f = 0; f < fallback.size(); ++f) {
      stats_.fallback_matches += unguided[f].size();
      results[fallback_index[f]] = std::move(unguided[f]);
    }
  }
  stats_.pairs_fallback += fallback.size();
  stats_.seconds_fallback += SecondsSince(t0);
  return results;
}

std::string DescribeGuidedMatching(const GuidedMatchingStats& g, const GuidedMatchingOptions& options) {
  std::ostringstream text;
  text << std::fixed << std::setprecision(3) << "Guided matching: " << g.pairs << " pairs, " << g.pairs_enough_matches
       << " with >= " << options.min_num_matches << " top-scale matches (" << g.stage1_matches << " in all), "
       << g.pairs_guided;
  if (g.searched_in_band) {
    text << " matched within the epipolar band (" << g.stage2_matches << " matches)";
  } else {
    text << " guided (" << g.stage2_matches << " of their " << g.stage2_exact_matches
         << " exact matches within the epipolar band)";
  }
  if (options.unguided_fallback) {
    text << ", " << g.pairs_fallback << " without the band (" << g.pairs_weak << " of them with "
         << options.fallback_min_num_matches << " to " << options.min_num_matches - 1 << " top-scale matches; "
         << g.fallback_matches << " matches)";
  } else {
    text << ", " << g.pairs_enough_matches - g.pairs_guided << " failed the inlier test";
  }
  text << "; stage 1 " << g.seconds_stage1 << " s, F " << g.seconds_fundamental << " s, stage 2 " << g.seconds_stage2
       << " s";
  if (options.unguided_fallback) text << ", without the band " << g.seconds_fallback << " s";
  return text.str();
}

}  // namespace cashash
