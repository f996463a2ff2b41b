// COLMAP's SIFT match acceptance on the angle between descriptors. Stored
// descriptors have norm ~512, so dot / 512^2 is the cosine.
#pragma once

#include <algorithm>
#include <cmath>

namespace cashash {

constexpr float kSiftDotNormalisation = 1.0f / (512.0f * 512.0f);

inline float DescriptorDotToAngle(int dot) {
  return std::acos(std::min(kSiftDotNormalisation * static_cast<float>(dot), 1.0f));
}

// best_dot / second_dot: integer dot products of the best and second best
// candidates (second_dot = 0 when there is no second candidate).
inline bool AcceptSiftMatch(int best_dot, int second_dot, float max_ratio, float max_distance) {
  const float best_angle = DescriptorDotToAngle(best_dot);
  if (best_angle > max_distance) return false;
  const float second_angle = DescriptorDotToAngle(second_dot);
  return best_angle < max_ratio * second_angle;
}

}  // namespace cashash
