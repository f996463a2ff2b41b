#include "cashash/cascade_matcher.h"

#include <algorithm>
#include <stdexcept>

#include "cashash/descriptor_distance.h"

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
  unique_candidates += other.unique_candidates;
  within_tau += other.within_tau;
  ranked += other.ranked;
}

void CascadeScratch::Reset(size_t num_targets) {
  stamps_.assign(num_targets, 0);
  stamp_ = 0;
}

namespace {

inline int DescriptorDot(const uint8_t* a, const uint8_t* b) {
  int dot = 0;
  for (int d = 0; d < kDescriptorDim; ++d) dot += static_cast<int>(a[d]) * static_cast<int>(b[d]);
  return dot;
}

}  // namespace

// Steps 4 and 5 of the definition for one query feature.
class CascadeQuery {
 public:
  CascadeQuery(const CascadeImage& query, const CascadeImage& target,
               const SiftMatchingOptions& sift_options, const CasHashOptions& options,
               CascadeScratch* scratch, CascadeStats* stats)
      : query_(query),
        target_(target),
        max_ratio_(static_cast<float>(sift_options.max_ratio)),
        max_distance_(static_cast<float>(sift_options.max_distance)),
        tau_(options.tau),
        top_k_(static_cast<size_t>(options.top_k)),
        scratch_(*scratch),
        stats_(stats) {
    if (query.hashed.num_tables != target.hashed.num_tables ||
        query.buckets.bits_per_table != target.buckets.bits_per_table) {
      throw std::invalid_argument("Cascade matching: images hashed with different tables");
    }
    scratch_.Reset(target.num_features());
  }

  ~CascadeQuery() {
    if (stats_ != nullptr) stats_->Add(local_stats_);
  }

  // Index of the accepted best match in the target, or -1.
  int Match(size_t q) {
    const int num_tables = query_.hashed.num_tables;
    const uint64_t code0 = query_.hashed.remap_codes[2 * q];
    const uint64_t code1 = query_.hashed.remap_codes[2 * q + 1];
    const uint32_t* query_buckets = query_.hashed.bucket_ids.data() + q * num_tables;
    const uint64_t* target_codes = target_.hashed.remap_codes.data();
    uint32_t* stamps = scratch_.stamps_.data();
    const uint32_t stamp = ++scratch_.stamp_;
    std::vector<uint64_t>& keys = scratch_.keys_;
    keys.clear();

    uint64_t entries = 0;
    uint64_t unique = 0;
    for (int t = 0; t < num_tables; ++t) {
      const uint32_t* it = target_.buckets.begin(t, query_buckets[t]);
      const uint32_t* end = target_.buckets.end(t, query_buckets[t]);
      entries += static_cast<uint64_t>(end - it);
      for (; it != end; ++it) {
        const uint32_t f = *it;
        if (stamps[f] == stamp) continue;
        stamps[f] = stamp;
        ++unique;
        const int hamming = __builtin_popcountll(code0 ^ target_codes[2 * f]) +
                            __builtin_popcountll(code1 ^ target_codes[2 * f + 1]);
        // Key order = (Hamming distance, feature index) ascending.
        if (hamming <= tau_) keys.push_back((static_cast<uint64_t>(hamming) << 32) | f);
      }
    }
    const size_t num_ranked = std::min(top_k_, keys.size());
    if (num_ranked < keys.size()) {
      std::nth_element(keys.begin(), keys.begin() + num_ranked, keys.end());
    }
    ++local_stats_.num_queries;
    local_stats_.bucket_entries += entries;
    local_stats_.unique_candidates += unique;
    local_stats_.within_tau += keys.size();
    local_stats_.ranked += num_ranked;

    // Best and second best by (dot descending, index ascending); the order
    // of the ranked keys does not matter.
    const uint8_t* query_desc = query_.descriptors.row(q);
    int best_dot = -1;
    int64_t best_index = -1;
    int second_dot = 0;
    for (size_t r = 0; r < num_ranked; ++r) {
      const uint32_t f = static_cast<uint32_t>(keys[r]);
      const int dot = DescriptorDot(query_desc, target_.descriptors.row(f));
      if (dot > best_dot || (dot == best_dot && f < best_index)) {
        second_dot = std::max(second_dot, best_dot);
        best_dot = dot;
        best_index = f;
      } else {
        second_dot = std::max(second_dot, dot);
      }
    }
    if (best_index < 0 || best_dot <= 0) return -1;
    if (!AcceptSiftMatch(best_dot, second_dot, max_ratio_, max_distance_)) return -1;
    return static_cast<int>(best_index);
  }

 private:
  const CascadeImage& query_;
  const CascadeImage& target_;
  const float max_ratio_;
  const float max_distance_;
  const int tau_;
  const size_t top_k_;
  CascadeScratch& scratch_;
  CascadeStats* stats_;
  CascadeStats local_stats_;
};

std::vector<int> CascadeMatchOneWay(const CascadeImage& query, const CascadeImage& target,
                                    const SiftMatchingOptions& sift_options,
                                    const CasHashOptions& options, CascadeScratch* scratch,
                                    CascadeStats* stats) {
  std::vector<int> matches(query.num_features(), -1);
  if (query.num_features() == 0 || target.num_features() == 0) return matches;
  CascadeQuery matcher(query, target, sift_options, options, scratch, stats);
  for (size_t q = 0; q < matches.size(); ++q) matches[q] = matcher.Match(q);
  return matches;
}

FeatureMatches CascadeMatchPair(const CascadeImage& image1, const CascadeImage& image2,
                                const SiftMatchingOptions& sift_options,
                                const CasHashOptions& options, CascadeScratch* scratch,
                                CascadeStats* stats) {
  FeatureMatches matches;
  if (image1.num_features() == 0 || image2.num_features() == 0) return matches;
  const std::vector<int> forward =
      CascadeMatchOneWay(image1, image2, sift_options, options, scratch, stats);
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
  CascadeQuery reverse_matcher(image2, image1, sift_options, options, scratch, stats);
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

}  // namespace cashash
