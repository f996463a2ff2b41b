// The Sturm root finder of the 5-point solver (sturm_roots.h): the roots of
// known polynomials, and the step-by-step path the GPU's warp takes giving
// the one-thread path's roots to the bit.
#include "cashash/geometry/sturm_roots.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <utility>
#include <vector>

namespace cashash {
namespace {

// Coefficients (ascending) of lead * prod (t - r) * prod (t^2 - 2 re t + |c|^2).
std::vector<double> Expand(const std::vector<double>& real_roots,
                           const std::vector<std::pair<double, double>>& complex_pairs, double lead) {
  std::vector<double> c = {lead};
  auto times = [&](const std::vector<double>& f) {
    std::vector<double> out(c.size() + f.size() - 1, 0.0);
    for (size_t i = 0; i < c.size(); ++i)
      for (size_t j = 0; j < f.size(); ++j) out[i + j] += c[i] * f[j];
    c = out;
  };
  for (double r : real_roots) times({-r, 1.0});
  for (auto [re, im] : complex_pairs) times({re * re + im * im, -2 * re, 1.0});
  return c;
}

struct Case {
  std::vector<double> real;
  std::vector<std::pair<double, double>> complex;
  double lead;
};

const std::vector<Case>& KnownCases() {
  static const std::vector<Case> cases = {
      {{-3, -1, -0.5, 0.1, 0.2, 0.7, 1.5, 2, 4, 9}, {}, 1.0},
      {{-2.5, 0.3, 1.7, 30.0}, {{0.5, 1.0}, {-1, 0.2}, {2, 3}}, -0.02},
      {{0.25, 0.2501, -7, 3}, {{1, 1}, {0, 2}, {-3, 0.5}}, 5e3},
      {{}, {{1, 1}, {0, 2}, {-3, 0.5}, {4, 0.01}, {0.1, 0.1}}, 1.0},
      {{1e-3, -2e-3, 12.0, -40.0, 100.0, 0.5}, {{1, 1}, {2, 2}}, 1e-4},
  };
  return cases;
}

TEST(SturmRoots, RootsOfKnownPolynomials) {
  for (const Case& c : KnownCases()) {
    const std::vector<double> coefficients = Expand(c.real, c.complex, c.lead);
    ASSERT_EQ(coefficients.size(), 11u);
    double roots[10];
    const int n = sturm::RealRoots(coefficients.data(), 10, roots);
    ASSERT_EQ(n, static_cast<int>(c.real.size()));
    std::vector<double> found(roots, roots + n), expected = c.real;
    std::sort(found.begin(), found.end());
    std::sort(expected.begin(), expected.end());
    for (int i = 0; i < n; ++i) EXPECT_NEAR(found[i], expected[i], 1e-8 * std::max(1.0, std::fabs(expected[i])));
  }
}

TEST(SturmRoots, ZeroConstantAndNonFinitePolynomialsHaveNoRoots) {
  double roots[10];
  const double zero[11] = {0};
  EXPECT_EQ(sturm::RealRoots(zero, 10, roots), 0);
  double constant[11] = {0};
  constant[0] = 3.0;
  EXPECT_EQ(sturm::RealRoots(constant, 10, roots), 0);
  double not_finite[11] = {1, 2, 3};
  not_finite[10] = std::nan("");
  EXPECT_EQ(sturm::RealRoots(not_finite, 10, roots), 0);
}

TEST(SturmRoots, SignChangesSkipZeros) {
  const double values[6] = {1.0, 0.0, -2.0, 0.0, 0.0, 3.0};
  EXPECT_EQ(sturm::SignChanges(values, 6), 2);
  EXPECT_EQ(sturm::SignChanges(values, 2), 0);
  const double zeros[3] = {0.0, -0.0, 0.0};
  EXPECT_EQ(sturm::SignChanges(zeros, 3), 0);
}

// The GPU's warp evaluates each polynomial of the sequence on its own lane
// and polishes each root on its own lane. Here the same split on one
// thread: values gathered polynomial by polynomial in reverse order, roots
// polished last first. Both must give RealRoots' roots, bit for bit, on
// random degree-10 polynomials with real and complex roots.
TEST(SturmRoots, StepByStepPathGivesTheOneThreadRootsBitForBit) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> root(-5.0, 5.0), lead(0.1, 10.0);
  std::uniform_int_distribution<int> num_real(0, 5);
  int total_roots = 0;
  for (int trial = 0; trial < 500; ++trial) {
    const int real = 2 * num_real(rng);  // 0..10, the complex pairs fill up to 10
    std::vector<double> reals;
    std::vector<std::pair<double, double>> complex;
    for (int i = 0; i < real; ++i) reals.push_back(root(rng));
    for (int i = 0; i < (10 - real) / 2; ++i) complex.push_back({root(rng), 0.01 + std::fabs(root(rng))});
    const std::vector<double> c = Expand(reals, complex, lead(rng));
    double expected[10];
    const int n = sturm::RealRoots(c.data(), 10, expected);
    sturm::SturmSequence seq;
    ASSERT_TRUE(sturm::BuildSturmSequence(c.data(), 10, &seq));
    auto gathered = [&seq](double t) {
      double values[sturm::kMaxSturmLength];
      for (int k = seq.length - 1; k >= 0; --k) values[k] = sturm::Horner(seq.S[k], seq.deg[k], t);
      return sturm::SignChanges(values, seq.length);
    };
    sturm::RootInterval intervals[sturm::kMaxDegree];
    const int num = sturm::IsolateRoots(seq, gathered, intervals);
    ASSERT_EQ(num, n);
    double found[10];
    for (int r = num - 1; r >= 0; --r) found[r] = sturm::RootIn(seq, intervals[r]);
    EXPECT_EQ(std::memcmp(found, expected, sizeof(double) * n), 0) << "trial " << trial;
    total_roots += n;
  }
  EXPECT_GT(total_roots, 1000);
}

}  // namespace
}  // namespace cashash
