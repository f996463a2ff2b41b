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
  // 2^bits_per_table per table).
  int num_tables = 6;
  int bits_per_table = 8;
  // Length of the second-level remap code used for Hamming ranking. Fixed at
  // 128 bits (two 64-bit words) in every backend.
  static constexpr int kRemapBits = 128;
  // Candidates whose remap Hamming distance exceeds tau are dropped before
  // ranking (the paper's threshold).
  int tau = 48;
  // Number of nearest candidates by Hamming distance whose exact descriptor
  // distance is computed.
  int top_k = 10;
  // Seed of the random projections; the same seed gives the same matches.
  uint64_t random_seed = 0;

  std::string Check() const;
};

std::string MatcherTypeToString(MatcherType type);
// Returns false on an unknown name.
bool MatcherTypeFromString(const std::string& name, MatcherType* type);

}  // namespace cashash
