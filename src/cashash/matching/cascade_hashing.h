// Cascade Hashing (Cheng et al. 2014; GPU version by Xu, Sun, Tao): the
// parts that every backend must share bit for bit, so that the CPU and GPU
// paths give the same matches for the same --CasHash.random_seed.
//
// Definition (all backends):
//  1. x = descriptor (uint8) - round(global mean descriptor), rounding half
//     away from zero (ComputeMeanDescriptor already returns integers).
//  2. Projection rows are drawn on the host from the seed: first
//     num_tables * bits_per_table rows for the bucket hashes, then 128 rows
//     for the remap code. Bit j of a feature is (dot(row_j, x) > 0); a dot of
//     exactly 0 gives bit 0. Every entry is an integer in [-255, 255] (stored
//     as float) and every x_d an integer in [-255, 255], so each dot is an
//     integer below 2^24 in magnitude: float32, TF32 or bf16 inputs with
//     float32 accumulation in any order, or int32 arithmetic, all give the
//     same bits.
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
//     second best defaulting to dot 0 (angle pi/2) when there is none. A best
//     dot of 0 is never a match (COLMAP's brute force keeps no best then).
//     5b. Thin lists (unguided matching only): a match accepted from fewer
//     than kThinListSize ranked candidates is decided again with the
//     kBeyondTauCandidates nearest candidates beyond tau added (smallest
//     (Hamming distance, feature index) among the features of B sharing a
//     bucket with q whose distance exceeds tau): best and second best of
//     the enlarged set, same rule. Why: with one or two candidates within
//     tau the second best defaults to a far one, so chance matches between
//     images that do not overlap passed the ratio test (10x exact
//     matching's on a generated street); the true second best lies just
//     beyond tau. Only accepted matches are re-decided, so the nearest
//     candidates beyond tau are looked up for few queries on the GPU.
//  6. Cross check keeps i->j only if j->i is the result of B against A.
//
// Projection entries: clamp(round(64 * g), -255, 255) with g an approximate
// standard normal, (sum of 12 uniform 32-bit integers) / 2^32 - 6, the
// integers drawn in row-major order from splitmix64 started at random_seed.
// Integer arithmetic only, so the matrix is the same on every platform.
#pragma once

#include <cstdint>
#include <vector>

#include "cashash/matching/mean_descriptor.h"
#include "cashash/matching/matching_options.h"
#include "cashash/base/types.h"

namespace cashash {

// Step 5b of the definition above.
constexpr int kThinListSize = 4;
constexpr int kBeyondTauCandidates = 2;

struct CascadeProjections {
  int num_tables = 0;
  int bits_per_table = 0;
  // (num_tables * bits_per_table + 128) x 128, row-major.
  std::vector<float> matrix;

  int num_bucket_rows() const { return num_tables * bits_per_table; }
  int num_rows() const { return num_bucket_rows() + CasHashOptions::kRemapBits; }
};

// Deterministic for a given seed on every platform (own integer normal
// sampler, not std::normal_distribution whose output is
// implementation-defined); see the definition above.
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
