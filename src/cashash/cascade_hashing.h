// Cascade Hashing (Cheng et al. 2014; GPU version by Xu, Sun, Tao): the
// parts that every backend must share bit for bit, so that the CPU and GPU
// paths give the same matches for the same --CasHash.random_seed.
//
// Definition (all backends):
//  1. x = descriptor (uint8 -> float) - global mean descriptor.
//  2. Projection rows are drawn on the host from the seed: first
//     num_tables * bits_per_table rows for the bucket hashes, then 128 rows
//     for the remap code. Bit j of a feature is (dot(row_j, x) > 0).
//  3. Bucket of table t = bits t*b .. t*b+b-1, bit i of the bucket id being
//     row t*b+i. Remap code bit i (0..127) goes to word i/64, bit i%64.
//  4. For a query q of image A against image B: candidates are the features
//     of B sharing q's bucket in at least one table (each counted once);
//     candidates with remap Hamming distance > tau are dropped; the top_k
//     remaining by (Hamming distance, feature index) ascending are kept.
//  5. Exact similarity is the integer dot product of the uint8 descriptors;
//     best and second best by (dot descending, index ascending). The match is
//     then accepted with COLMAP's rule (see descriptor_distance.h): angle of
//     best <= max_distance and angle(best) < max_ratio * angle(second), the
//     second best defaulting to dot 0 (angle pi/2) when there is none.
//  6. Cross check keeps i->j only if j->i is the result of B against A.
#pragma once

#include <cstdint>
#include <vector>

#include "cashash/feature_matcher.h"
#include "cashash/matching_options.h"
#include "cashash/types.h"

namespace cashash {

struct CascadeProjections {
  int num_tables = 0;
  int bits_per_table = 0;
  // (num_tables * bits_per_table + 128) x 128, row-major.
  std::vector<float> matrix;

  int num_bucket_rows() const { return num_tables * bits_per_table; }
  int num_rows() const { return num_bucket_rows() + CasHashOptions::kRemapBits; }
};

// Deterministic for a given seed on every platform (own normal sampler, not
// std::normal_distribution whose output is implementation-defined).
CascadeProjections GenerateCascadeProjections(const CasHashOptions& options);

// Hash codes of one image.
struct HashedFeatures {
  size_t num_features = 0;
  int num_tables = 0;
  // 2 words per feature: remap code bits 0..63, 64..127.
  std::vector<uint64_t> remap_codes;
  // num_tables entries per feature (feature-major): bucket id in table t.
  std::vector<uint32_t> bucket_ids;
};

// Hashes the first num_rows descriptors (num_rows <= descriptors.rows()).
HashedFeatures HashDescriptors(const FeatureDescriptors& descriptors, size_t num_rows,
                               const CascadeProjections& projections, const MeanDescriptor& mean);

}  // namespace cashash
