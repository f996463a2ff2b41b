// Options of the descriptor matching step. SiftMatchingOptions carries
// COLMAP's names and defaults so that results are comparable; CasHashOptions
// carries the Cascade Hashing parameters of our own matcher.
#pragma once

#include <cstdint>
#include <string>

namespace cashash {

struct SiftMatchingOptions {
  // Number of CPU threads; -1 uses every core (COLMAP's convention).
  int num_threads = -1;
  // Lowe's ratio test on the angle between descriptors: reject when
  // best >= max_ratio * second_best.
  double max_ratio = 0.8;
  // Reject when the best angle (radians, acos(dot / 512^2)) exceeds this.
  double max_distance = 0.7;
  // Keep mutual best matches only.
  bool cross_check = true;
  // Images with more features are truncated to the first max_num_matches
  // rows, as COLMAP does.
  int max_num_matches = 32768;

  // Returns an empty string when valid, else a message naming the option.
  std::string Check() const;
};

enum class MatcherType { kCascade, kBruteForce };

struct CasHashOptions {
  // cascade | bruteforce ("--CasHash.matcher").
  MatcherType matcher = MatcherType::kCascade;
  // Number of first-level hash tables and bits per table (bucket count is
  // 2^bits_per_table per table). What users check is how many of the exact
  // matcher's *verified* inliers survive, and that follows the raw recall
  // closely. On fountain-P11 (55 pairs, exact mutual ratio-test matches as
  // reference; docs/cascade_parameters.md): 7 x 8 keeps 93.2 %, 8 x 8 94.8 %,
  // 8 x 7 96.7 % at ~1,100 bucket entries per query and half the speed of
  // 7 x 8, 9 x 7 97.6 % at 0.8x the speed of 8 x 7. 8 x 7 is the cheapest
  // setting that keeps 95 % of the exact verified inliers; faster settings
  // are one option away (--CasHash.num_tables 7 --CasHash.bits_per_table 8).
  // The GPU backend needs num_tables * bits_per_table <= 64.
  int num_tables = 8;
  int bits_per_table = 7;
  // Length of the second-level remap code used for Hamming ranking. Fixed at
  // 128 bits (two 64-bit words) in every backend.
  static constexpr int kRemapBits = 128;
  // Candidates whose remap Hamming distance exceeds tau are dropped before
  // ranking (the paper's threshold). 40 loses no recall against 48 or 128
  // on real SIFT and leaves a third of the candidates of 48 to rank.
  int tau = 40;
  // Number of nearest candidates by Hamming distance whose exact descriptor
  // distance is computed. Recall hardly depends on it (5: -0.5 %, 15:
  // +0.1 %): a true match that shares a bucket at all ranks near the top.
  int top_k = 10;
  // Seed of the random projections; the same seed gives the same matches.
  uint64_t random_seed = 0;

  std::string Check() const;
};

std::string MatcherTypeToString(MatcherType type);
// Returns false on an unknown name.
bool MatcherTypeFromString(const std::string& name, MatcherType* type);

}  // namespace cashash
