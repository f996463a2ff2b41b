// The running best and second best dot of each feature, shared by the
// brute-force kernels (brute_force_matcher.cc, brute_force_int8.cc).
#pragma once

#include <cstddef>

#include "cashash/matching/brute_force_matcher.h"

namespace cashash {

// Candidates arrive in ascending index order and only a strictly larger dot
// replaces the best, so ties keep the lowest index (COLMAP's loop does the
// same).
inline void UpdateBestTwo(int dot, int index, int* best_dot, int* best_index, int* second_dot) {
  if (dot > *best_dot) {
    *second_dot = *best_dot;
    *best_dot = dot;
    *best_index = index;
  } else if (dot > *second_dot) {
    *second_dot = dot;
  }
}

inline void InitBestTwo(size_t n, BestTwo* best) {
  best->best_dot.assign(n, 0);
  best->best_index.assign(n, -1);
  best->second_dot.assign(n, 0);
}

// Both trackers of dot(a row i, b column j).
inline void UpdateBothWays(int dot, size_t i, size_t j, BestTwo* rows, BestTwo* cols) {
  UpdateBestTwo(dot, static_cast<int>(j), &rows->best_dot[i], &rows->best_index[i], &rows->second_dot[i]);
  UpdateBestTwo(dot, static_cast<int>(i), &cols->best_dot[j], &cols->best_index[j], &cols->second_dot[j]);
}

// The int8 kernels (brute_force_int8.cc): a laid out as rows, b as
// columns, trackers sized to the padded rows and columns.
void BestTwoInt8Vnni512(const WideDescriptors& a, const WideDescriptors& b, BestTwo* a_to_b, BestTwo* b_to_a);
void BestTwoInt8AvxVnni(const WideDescriptors& a, const WideDescriptors& b, BestTwo* a_to_b, BestTwo* b_to_a);
// Whether the processor runs them (and the build has them).
bool ProcessorHasVnni512();
bool ProcessorHasAvxVnni();

}  // namespace cashash
