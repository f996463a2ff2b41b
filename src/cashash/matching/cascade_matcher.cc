#include "cashash/matching/cascade_matcher.h"

#include <algorithm>
#include <stdexcept>
#include <string>

#include "cashash/matching/descriptor_distance.h"
#include "cashash/matching/epipolar_band.h"

#if defined(__AVX2__)
#include <immintrin.h>
#endif

namespace cashash {

BucketTables BuildBucketTables(const HashedFeatures& hashed, int bits_per_table) {
  if (bits_per_table < 1 || bits_per_table > 31) {
    throw std::invalid_argument("BuildBucketTables: bits_per_table out of range");
  }
  BucketTables tables;
  tables.num_tables = hashed.num_tables;
  tables.bits_per_table = bits_per_table;
  tables.num_features = hashed.num_features;
  const size_t num_buckets = tables.num_buckets();
  const size_t n = hashed.num_features;
  const int num_tables = hashed.num_tables;
  tables.offsets.assign(num_tables * (num_buckets + 1), 0);
  tables.features.resize(num_tables * n);
  tables.codes.resize(2 * num_tables * n);
  for (int t = 0; t < num_tables; ++t) {
    uint32_t* offsets = tables.offsets.data() + t * (num_buckets + 1);
    // Counting sort: histogram, exclusive prefix sum, stable scatter.
    for (size_t i = 0; i < n; ++i) {
      const uint32_t bucket = hashed.bucket_ids[i * num_tables + t];
      if (bucket >= num_buckets) throw std::invalid_argument("BuildBucketTables: bucket id out of range");
      ++offsets[bucket + 1];
    }
    for (size_t b = 0; b < num_buckets; ++b) offsets[b + 1] += offsets[b];
    std::vector<uint32_t> cursor(offsets, offsets + num_buckets);
    uint32_t* features = tables.features.data() + t * n;
    for (size_t i = 0; i < n; ++i) {
      features[cursor[hashed.bucket_ids[i * num_tables + t]]++] = static_cast<uint32_t>(i);
    }
    for (size_t p = 0; p < n; ++p) {
      tables.codes[2 * (t * n + p)] = hashed.remap_codes[2 * features[p]];
      tables.codes[2 * (t * n + p) + 1] = hashed.remap_codes[2 * features[p] + 1];
    }
  }
  return tables;
}

CascadeImage BuildCascadeImage(const FeatureDescriptors& descriptors, size_t num_rows,
                               const CascadeProjections& projections, const MeanDescriptor& mean) {
  num_rows = std::min(num_rows, descriptors.rows());
  CascadeImage image;
  image.descriptors.data.assign(descriptors.data.begin(),
                                descriptors.data.begin() + num_rows * kDescriptorDim);
  image.hashed = HashDescriptors(image.descriptors, num_rows, projections, mean);
  image.buckets = BuildBucketTables(image.hashed, projections.bits_per_table);
  return image;
}

void CascadeStats::Add(const CascadeStats& other) {
  num_queries += other.num_queries;
  bucket_entries += other.bucket_entries;
  within_tau += other.within_tau;
  ranked += other.ranked;
}

void CascadeScratch::Reset(size_t num_targets) {
  seen_.assign((num_targets + 63) / 64, 0);
}

namespace {

// tau and the rest chosen for the run are decided before matching
// (CasHashOptions::CheckDecided): a tau of 0 would keep only the candidates
// of equal remap codes.
void RequireDecided(const CasHashOptions& options) {
  const std::string undecided = options.CheckDecided();
  if (!undecided.empty()) throw std::invalid_argument(undecided);
}

inline int DescriptorDot(const uint8_t* a, const uint8_t* b) {
#if defined(__AVX2__)
  __m256i sum = _mm256_setzero_si256();
  for (int k = 0; k < kDescriptorDim; k += 16) {
    const __m256i x = _mm256_cvtepu8_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(a + k)));
    const __m256i y = _mm256_cvtepu8_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(b + k)));
    sum = _mm256_add_epi32(sum, _mm256_madd_epi16(x, y));
  }
  __m128i s = _mm_add_epi32(_mm256_castsi256_si128(sum), _mm256_extracti128_si256(sum, 1));
  s = _mm_add_epi32(s, _mm_shuffle_epi32(s, _MM_SHUFFLE(1, 0, 3, 2)));
  s = _mm_add_epi32(s, _mm_shuffle_epi32(s, _MM_SHUFFLE(2, 3, 0, 1)));
  return _mm_cvtsi128_si32(s);
#else
  int dot = 0;
  for (int d = 0; d < kDescriptorDim; ++d) dot += static_cast<int>(a[d]) * static_cast<int>(b[d]);
  return dot;
#endif
}

}  // namespace

// Steps 4 and 5 of the definition for one query feature.
class CascadeQuery {
 public:
  CascadeQuery(const CascadeImage& query, const CascadeImage& target,
               const SiftMatchingOptions& sift_options, const CasHashOptions& options,
               CascadeScratch* scratch, CascadeStats* stats,
               const EpipolarGuidance* guidance = nullptr, bool reverse = false)
      : query_(query),
        target_(target),
        max_ratio_(static_cast<float>(sift_options.max_ratio)),
        max_distance_(static_cast<float>(sift_options.max_distance)),
        tau_(options.tau),
        top_k_(static_cast<size_t>(options.top_k)),
        scratch_(*scratch),
        stats_(stats),
        guidance_(guidance),
        reverse_(reverse) {
    if (query.hashed.num_tables != target.hashed.num_tables ||
        query.buckets.bits_per_table != target.buckets.bits_per_table) {
      throw std::invalid_argument("Cascade matching: images hashed with different tables");
    }
    scratch_.Reset(target.num_features());
  }

  ~CascadeQuery() {
    if (stats_ != nullptr) stats_->Add(local_stats_);
  }

  // Index of the accepted best match in the target, or -1. With guidance,
  // only candidates within the band around q's epipolar line are ranked.
  int Match(size_t q) {
    if (guidance_ == nullptr) return MatchInBand<false>(q, EpipolarLine(), nullptr);
    const float* query_points = reverse_ ? guidance_->points2 : guidance_->points1;
    const float* target_points = reverse_ ? guidance_->points1 : guidance_->points2;
    const EpipolarLine line = reverse_ ? LineInFirstImage(guidance_->F, query_points[2 * q], query_points[2 * q + 1])
                                       : LineInSecondImage(guidance_->F, query_points[2 * q], query_points[2 * q + 1]);
    return MatchInBand<true>(q, line, target_points);
  }

 private:
  // One function because the branch-free bucket scan, the top_k cut and the
  // best-two pass (with the thin-list rescan) share the query's codes, the
  // scratch keys and histogram, and the best/second state of `consider`.
  template <bool kBand>
  int MatchInBand(size_t q, const EpipolarLine& line, const float* target_points) {
    const double max_band_distance = kBand ? guidance_->max_distance : 0.0;
    const int num_tables = query_.hashed.num_tables;
    const uint64_t code0 = query_.hashed.remap_codes[2 * q];
    const uint64_t code1 = query_.hashed.remap_codes[2 * q + 1];
    const uint32_t* query_buckets = query_.hashed.bucket_ids.data() + q * num_tables;
    uint64_t* seen = scratch_.seen_.data();
    const int tau = tau_;
    const uint32_t* features = target_.buckets.features.data();
    const uint64_t* codes = target_.buckets.codes.data();

    size_t entries = 0;
    for (int t = 0; t < num_tables; ++t) {
      entries += target_.buckets.end(t, query_buckets[t]) - target_.buckets.begin(t, query_buckets[t]);
    }
    std::vector<uint64_t>& keys = scratch_.keys_;
    if (keys.size() < entries) keys.resize(entries);
    uint32_t* histogram = scratch_.histogram_.data();
    std::fill(histogram, histogram + tau + 1, 0u);

    // Branch-free scan: whether an entry is kept (within tau and not yet a
    // candidate of this query) is unpredictable, so it is computed, not
    // branched on.
    size_t num_keys = 0;
    for (int t = 0; t < num_tables; ++t) {
      const size_t end = target_.buckets.end(t, query_buckets[t]);
      for (size_t p = target_.buckets.begin(t, query_buckets[t]); p < end; ++p) {
        const int hamming = __builtin_popcountll(code0 ^ codes[2 * p]) +
                            __builtin_popcountll(code1 ^ codes[2 * p + 1]);
        const uint32_t f = features[p];
        const uint64_t bit = uint64_t{1} << (f % 64);
        const uint64_t word = seen[f / 64];
        bool keep = hamming <= tau && (word & bit) == 0;
        if (kBand) keep = keep && line.Contains(target_points[2 * f], target_points[2 * f + 1], max_band_distance);
        seen[f / 64] = word | (keep ? bit : 0);
        // Key order = (Hamming distance, feature index) ascending.
        keys[num_keys] = (static_cast<uint64_t>(hamming) << 32) | f;
        num_keys += keep;
        histogram[keep ? hamming : 0] += keep;
      }
    }
    for (size_t i = 0; i < num_keys; ++i) seen[static_cast<uint32_t>(keys[i]) / 64] = 0;

    // The top_k keys: every key below the cut-off distance, then the lowest
    // indices at the cut-off distance.
    const size_t num_ranked = std::min(top_k_, num_keys);
    if (num_ranked < num_keys) {
      int cutoff = 0;
      size_t below = 0;
      while (below + histogram[cutoff] < num_ranked) below += histogram[cutoff++];
      uint64_t* ties = keys.data() + num_keys;  // scratch space behind the keys
      if (keys.size() < 2 * num_keys) {
        keys.resize(2 * num_keys);
        ties = keys.data() + num_keys;
      }
      size_t num_selected = 0, num_ties = 0;
      for (size_t i = 0; i < num_keys; ++i) {
        const int hamming = static_cast<int>(keys[i] >> 32);
        if (hamming < cutoff) {
          keys[num_selected++] = keys[i];
        } else if (hamming == cutoff) {
          ties[num_ties++] = keys[i];
        }
      }
      const size_t need = num_ranked - num_selected;
      if (need < num_ties) std::nth_element(ties, ties + need, ties + num_ties);
      std::copy(ties, ties + need, keys.begin() + num_selected);
    }
    ++local_stats_.num_queries;
    local_stats_.bucket_entries += entries;
    local_stats_.within_tau += num_keys;
    local_stats_.ranked += num_ranked;

    // Best and second best by (dot descending, index ascending); the order
    // of the ranked keys does not matter.
    const uint8_t* query_desc = query_.descriptors.row(q);
    int best_dot = -1;
    int64_t best_index = -1;
    int second_dot = 0;
    auto consider = [&](uint32_t f) {
      const int dot = DescriptorDot(query_desc, target_.descriptors.row(f));
      if (dot > best_dot || (dot == best_dot && f < best_index)) {
        second_dot = std::max(second_dot, best_dot);
        best_dot = dot;
        best_index = f;
      } else {
        second_dot = std::max(second_dot, dot);
      }
    };
    for (size_t r = 0; r < num_ranked; ++r) consider(static_cast<uint32_t>(keys[r]));
    if (best_index < 0 || best_dot <= 0) return -1;
    if (!AcceptSiftMatch(best_dot, second_dot, max_ratio_, max_distance_)) return -1;
    if (!kBand && num_ranked < static_cast<size_t>(kThinListSize)) {
      // Step 5b: a thin list's accepted match is decided again. The lookup
      // is a second pass over the buckets, for these few queries only, as
      // on the GPU, so that the scan above stays branch-free.
      uint64_t beyond[kBeyondTauCandidates];
      const int num_beyond = NearestBeyondTau(query_buckets, code0, code1, beyond);
      for (int b = 0; b < num_beyond; ++b) consider(static_cast<uint32_t>(beyond[b]));
      if (!AcceptSiftMatch(best_dot, second_dot, max_ratio_, max_distance_)) return -1;
    }
    return static_cast<int>(best_index);
  }

  // The kBeyondTauCandidates nearest distinct candidates beyond tau, as keys
  // (Hamming distance << 32 | feature) in ascending order; returns how many
  // there are.
  int NearestBeyondTau(const uint32_t* query_buckets, uint64_t code0, uint64_t code1, uint64_t* out) const {
    static_assert(kBeyondTauCandidates == 2, "two nearest candidates beyond tau are tracked");
    constexpr uint64_t kNone = ~uint64_t{0};
    uint64_t first = kNone, second = kNone;
    const uint32_t* features = target_.buckets.features.data();
    const uint64_t* codes = target_.buckets.codes.data();
    for (int t = 0; t < query_.hashed.num_tables; ++t) {
      const size_t end = target_.buckets.end(t, query_buckets[t]);
      for (size_t p = target_.buckets.begin(t, query_buckets[t]); p < end; ++p) {
        const int hamming = __builtin_popcountll(code0 ^ codes[2 * p]) +
                            __builtin_popcountll(code1 ^ codes[2 * p + 1]);
        const uint64_t key = (static_cast<uint64_t>(hamming) << 32) | features[p];
        if (hamming <= tau_ || key >= second || key == first) continue;
        if (key < first) {
          second = first;
          first = key;
        } else {
          second = key;
        }
      }
    }
    int count = 0;
    if (first != kNone) out[count++] = first;
    if (second != kNone) out[count++] = second;
    return count;
  }

  const CascadeImage& query_;
  const CascadeImage& target_;
  const float max_ratio_;
  const float max_distance_;
  const int tau_;
  const size_t top_k_;
  CascadeScratch& scratch_;
  CascadeStats* stats_;
  CascadeStats local_stats_;
  const EpipolarGuidance* guidance_;
  const bool reverse_;  // queries are features of image 2 (lines in image 1)
};

std::vector<int> CascadeMatchOneWay(const CascadeImage& query, const CascadeImage& target,
                                    const SiftMatchingOptions& sift_options,
                                    const CasHashOptions& options, CascadeScratch* scratch,
                                    CascadeStats* stats) {
  RequireDecided(options);
  std::vector<int> matches(query.num_features(), -1);
  if (query.num_features() == 0 || target.num_features() == 0) return matches;
  CascadeQuery matcher(query, target, sift_options, options, scratch, stats);
  for (size_t q = 0; q < matches.size(); ++q) matches[q] = matcher.Match(q);
  return matches;
}

namespace {

FeatureMatches MatchPairImpl(const CascadeImage& image1, const CascadeImage& image2,
                             const SiftMatchingOptions& sift_options, const CasHashOptions& options,
                             CascadeScratch* scratch, CascadeStats* stats, const EpipolarGuidance* guidance) {
  RequireDecided(options);
  FeatureMatches matches;
  if (image1.num_features() == 0 || image2.num_features() == 0) return matches;
  std::vector<int> forward(image1.num_features(), -1);
  {
    CascadeQuery forward_matcher(image1, image2, sift_options, options, scratch, stats, guidance, false);
    for (size_t q = 0; q < forward.size(); ++q) forward[q] = forward_matcher.Match(q);
  }
  if (!sift_options.cross_check) {
    for (size_t i = 0; i < forward.size(); ++i) {
      if (forward[i] >= 0) {
        matches.push_back({static_cast<point2D_t>(i), static_cast<point2D_t>(forward[i])});
      }
    }
    return matches;
  }
  // The result of a reverse query depends only on the queried feature, so
  // asking only for the hit features equals the full reverse pass.
  constexpr int kNotQueried = -2;
  std::vector<int> reverse(image2.num_features(), kNotQueried);
  CascadeQuery reverse_matcher(image2, image1, sift_options, options, scratch, stats, guidance, true);
  for (size_t i = 0; i < forward.size(); ++i) {
    const int j = forward[i];
    if (j < 0) continue;
    if (reverse[j] == kNotQueried) reverse[j] = reverse_matcher.Match(j);
    if (reverse[j] == static_cast<int>(i)) {
      matches.push_back({static_cast<point2D_t>(i), static_cast<point2D_t>(j)});
    }
  }
  return matches;
}

}  // namespace

FeatureMatches CascadeMatchPair(const CascadeImage& image1, const CascadeImage& image2,
                                const SiftMatchingOptions& sift_options,
                                const CasHashOptions& options, CascadeScratch* scratch,
                                CascadeStats* stats) {
  return MatchPairImpl(image1, image2, sift_options, options, scratch, stats, nullptr);
}

FeatureMatches CascadeMatchPairGuided(const CascadeImage& image1, const CascadeImage& image2,
                                      const EpipolarGuidance& guidance, const SiftMatchingOptions& sift_options,
                                      const CasHashOptions& options, CascadeScratch* scratch,
                                      CascadeStats* stats) {
  if (guidance.F == nullptr || guidance.points1 == nullptr || guidance.points2 == nullptr) {
    throw std::invalid_argument("CascadeMatchPairGuided: F and both images' keypoint positions are needed");
  }
  if (!(guidance.max_distance >= 0)) {
    throw std::invalid_argument("CascadeMatchPairGuided: the band's max_distance must be >= 0");
  }
  return MatchPairImpl(image1, image2, sift_options, options, scratch, stats, &guidance);
}

}  // namespace cashash
