// Random test data drawn one value a statement.
//
// The order in which a call's arguments are evaluated is unspecified: g++
// evaluates them last to first, clang first to last. So a scene built as
// `Eigen::Vector2d(uni(rng), uni(rng))` differs between the two compilers,
// and a test whose limits hold for one scene can fail on the other's.
// DrawLastFirst draws the last value first, the order the tests' data has
// always had under g++, so every compiler builds the data the limits were
// set on.
#pragma once

#include <array>

namespace cashash {
namespace testing_support {

// N values of `draw()`, the last drawn first.
template <int N, typename Draw>
std::array<double, N> DrawLastFirst(Draw&& draw) {
  std::array<double, N> values{};
  for (int i = N - 1; i >= 0; --i) values[i] = draw();
  return values;
}

}  // namespace testing_support
}  // namespace cashash
