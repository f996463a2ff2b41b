// Cascade Hashing matching of two hashed images on the CPU, following the
// definition in cascade_hashing.h (steps 4 to 6).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "cashash/matching/cascade_hashing.h"
#include "cashash/matching/matching_options.h"
#include "cashash/base/types.h"

namespace cashash {

// The features of one image grouped by bucket, one CSR table per hash table:
// bucket b of table t holds features[t * num_features + offsets[t * (B + 1) + b]
// .. + offsets[t * (B + 1) + b + 1]), B = 2^bits_per_table, in ascending
// feature order. Buckets have any size (counting sort, no fixed capacity), so
// many identical descriptors in one bucket lose nothing.
struct BucketTables {
  int num_tables = 0;
  int bits_per_table = 0;
  size_t num_features = 0;
  std::vector<uint32_t> offsets;
  std::vector<uint32_t> features;
  // The remap code of features[i] at codes[2 * i], codes[2 * i + 1]: ranking
  // then reads codes in bucket order instead of jumping across the image.
  std::vector<uint64_t> codes;

  size_t num_buckets() const { return size_t{1} << bits_per_table; }
  // [begin, end) positions in `features` of bucket `bucket` of table `table`.
  size_t begin(int table, uint32_t bucket) const {
    return table * num_features + offsets[table * (num_buckets() + 1) + bucket];
  }
  size_t end(int table, uint32_t bucket) const {
    return table * num_features + offsets[table * (num_buckets() + 1) + bucket + 1];
  }
};

BucketTables BuildBucketTables(const HashedFeatures& hashed, int bits_per_table);

// Everything matching needs of one image, computed once per image.
struct CascadeImage {
  FeatureDescriptors descriptors;  // truncated to the hashed rows
  HashedFeatures hashed;
  BucketTables buckets;

  size_t num_features() const { return hashed.num_features; }
};

// Hashes the first num_rows descriptors and builds the bucket tables.
CascadeImage BuildCascadeImage(const FeatureDescriptors& descriptors, size_t num_rows,
                               const CascadeProjections& projections, const MeanDescriptor& mean);

// Candidate counts summed over queries, to tune the parameters.
struct CascadeStats {
  uint64_t num_queries = 0;
  // Bucket entries visited: features sharing a bucket, counted once per
  // table they share (the Hamming distance is computed for each).
  uint64_t bucket_entries = 0;
  uint64_t within_tau = 0;  // distinct candidates with Hamming distance <= tau
  uint64_t ranked = 0;      // kept for the exact distance (<= top_k)

  void Add(const CascadeStats& other);
};

// Per-thread working memory, reusable across pairs.
class CascadeScratch {
 public:
  // Prepares for queries against an image with num_targets features.
  void Reset(size_t num_targets);

 private:
  friend class CascadeQuery;
  // One bit per target feature: "already a candidate of this query". Small
  // enough to stay in L1; each query clears the bits it set.
  std::vector<uint64_t> seen_;
  std::vector<uint64_t> keys_;
  // Candidates per Hamming distance, for the top_k selection.
  std::array<uint32_t, CasHashOptions::kRemapBits + 1> histogram_{};
};

// Best match in `target` of each feature of `query` (steps 4 and 5): one
// entry per query feature, the target index or -1. These functions throw
// std::invalid_argument for options with a value still chosen for the run
// (CasHashOptions::CheckDecided).
std::vector<int> CascadeMatchOneWay(const CascadeImage& query, const CascadeImage& target,
                                    const SiftMatchingOptions& sift_options,
                                    const CasHashOptions& options, CascadeScratch* scratch,
                                    CascadeStats* stats = nullptr);

// Matches of the pair (image1, image2), cross-checked when
// sift_options.cross_check (step 6), sorted by point2D_idx1. The reverse
// direction is queried only for the features that some forward match hits.
FeatureMatches CascadeMatchPair(const CascadeImage& image1, const CascadeImage& image2,
                                const SiftMatchingOptions& sift_options,
                                const CasHashOptions& options, CascadeScratch* scratch,
                                CascadeStats* stats = nullptr);

// Epipolar guidance of one pair (Ga-CasHash stage 2, guided_matching.h): a
// candidate j of query i is ranked only if it lies within max_distance pixels
// of i's epipolar line (epipolar_band.h); in the reverse direction of the
// cross-check the line is F^T x_j in image 1. Tested before the top_k
// selection, so the top_k candidates are the nearest ones inside the band.
struct EpipolarGuidance {
  const double* F = nullptr;  // row-major 3x3, x2^T F x1 = 0 in pixels
  // Keypoint pixels, x and y of feature i at [2 i] and [2 i + 1], for at
  // least the hashed rows of each image.
  const float* points1 = nullptr;
  const float* points2 = nullptr;
  double max_distance = 0;
};

// CascadeMatchPair with the candidates restricted to the epipolar band.
FeatureMatches CascadeMatchPairGuided(const CascadeImage& image1, const CascadeImage& image2,
                                      const EpipolarGuidance& guidance, const SiftMatchingOptions& sift_options,
                                      const CasHashOptions& options, CascadeScratch* scratch,
                                      CascadeStats* stats = nullptr);

}  // namespace cashash
