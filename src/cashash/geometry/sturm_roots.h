// Real roots of a polynomial of degree <= 10 (the 5-point solver's
// determinant in z), in plain C++ for the host and as CUDA device code: a
// Sturm sequence isolates each root in an interval, then safeguarded Newton
// steps polish it. (polynomial_roots.h holds the 7-point solver's cubic.)
//
// The steps are separate functions so that the GPU can give them to a warp
// (cuda/cashash_cuda/geometry/warp_five_point.cuh) and still compute every
// value the one-thread path computes: IsolateRoots takes the sign-variation
// count as a callable (a warp evaluates the sequence's polynomials on
// separate lanes), and each interval's root is polished on its own
// (a warp polishes one root per lane). RealRoots is the one-thread path.
#pragma once

#include <cmath>

#include "cashash/base/host_device.h"

namespace cashash {
namespace sturm {

#if !defined(__CUDA_ARCH__)
// Host pass: the standard overloads (device code gets CUDA's own).
using std::fabs;
using std::fmax;
using std::isfinite;
using std::pow;
#endif

constexpr int kMaxDegree = 10;
constexpr int kMaxSturmLength = kMaxDegree + 1;

CASHASH_HOST_DEVICE inline double Horner(const double* c, int degree, double t) {
  double v = c[degree];
  for (int i = degree - 1; i >= 0; --i) v = v * t + c[i];
  return v;
}

// Half the spacing of doubles at 1: the relative rounding of one operation.
constexpr double kUnitRoundoff = 1.1102230246251565e-16;

// A simple root of p in [lo, hi] (p(lo), p(hi) of opposite signs, else the
// best point reached): Newton steps, halving the bracket instead whenever
// Newton would leave it or shrink it more slowly than halving (a Newton step
// longer than half the step before: far from the root of a degree-10
// polynomial Newton creeps), and done once |p(x)| is within Horner's rounding
// bound, where the sign of p, and so any further step, is noise. Without
// those two rules a sample of random correspondences took 71 steps for its
// roots (16.7 a root, 19 % of roots 30 or more, mostly halvings inside the
// noise); with them 33 (7.7 a root), and the slowest of 32 samples, which a
// warp waits for, 52 instead of 158.
CASHASH_HOST_DEVICE inline double PolishRoot(const double* p, int degree, double lo, double hi) {
  double f_lo = Horner(p, degree, lo);
  const double f_hi = Horner(p, degree, hi);
  if (f_lo == 0) return lo;
  if (f_hi == 0) return hi;
  const bool bracketed = (f_lo < 0) != (f_hi < 0);
  double x = 0.5 * (lo + hi);
  double step = hi - lo, step_before = step;
  for (int it = 0; it < 100; ++it) {
    double f = p[degree], df = 0, rounding = fabs(p[degree]);
    const double ax = fabs(x);
    for (int i = degree - 1; i >= 0; --i) {
      df = df * x + f;
      f = f * x + p[i];
      rounding = rounding * ax + fabs(p[i]);
    }
    if (fabs(f) <= 2 * degree * kUnitRoundoff * rounding) return x;  // f == 0 included
    if (bracketed) {
      if ((f < 0) == (f_lo < 0)) {
        lo = x;
        f_lo = f;
      } else {
        hi = x;
      }
    }
    double next = df != 0 ? x - f / df : 0.5 * (lo + hi);
    const bool creeping = bracketed && fabs(2 * f) > fabs(step_before * df);
    if (!(next > lo && next < hi) || creeping) next = 0.5 * (lo + hi);
    step_before = step;
    step = next - x;
    if (fabs(step) <= 1e-15 * fmax(1.0, ax)) return next;
    x = next;
  }
  return x;
}

// The Sturm sequence of a polynomial made monic: S[0] = p, S[1] = p' / n,
// then the negated remainders, until one divides exactly (the gcd) or a
// constant is reached. Fixed arrays: no allocation in device code.
struct SturmSequence {
  double S[kMaxSturmLength][kMaxSturmLength];
  int deg[kMaxSturmLength];
  int length;  // polynomials in S
  int degree;  // of S[0] once negligible leading coefficients are dropped
};

// False when the polynomial is zero, not finite or constant (no roots).
CASHASH_HOST_DEVICE inline bool BuildSturmSequence(const double* coefficients, int degree, SturmSequence* seq) {
  double scale = 0;
  for (int i = 0; i <= degree; ++i) scale = fmax(scale, fabs(coefficients[i]));
  if (!(scale > 0) || !isfinite(scale)) return false;
  int n = degree;
  while (n > 0 && fabs(coefficients[n]) <= 1e-14 * scale) --n;
  if (n == 0) return false;
  double (*S)[kMaxSturmLength] = seq->S;
  int* deg = seq->deg;
  for (int i = 0; i <= n; ++i) S[0][i] = coefficients[i] / coefficients[n];
  deg[0] = n;
  for (int i = 0; i < n; ++i) S[1][i] = S[0][i + 1] * (i + 1) / n;
  deg[1] = n - 1;
  int length = 2;
  while (length < kMaxSturmLength && deg[length - 1] > 0) {
    const double* u = S[length - 2];
    const double* w = S[length - 1];
    const int du = deg[length - 2], dw = deg[length - 1];
    double r[kMaxSturmLength];
    double u_max = 0;
    for (int i = 0; i <= du; ++i) {
      r[i] = u[i];
      u_max = fmax(u_max, fabs(u[i]));
    }
    for (int k = du - dw; k >= 0; --k) {
      const double q = r[dw + k] / w[dw];
      for (int j = 0; j <= dw; ++j) r[j + k] -= q * w[j];
    }
    int dr = dw - 1;
    while (dr >= 0 && fabs(r[dr]) <= 1e-14 * u_max) --dr;
    if (dr < 0) break;  // exact division: the sequence ends at the gcd
    const double lead = fabs(r[dr]);
    for (int j = 0; j <= dr; ++j) S[length][j] = -r[j] / lead;
    deg[length] = dr;
    ++length;
  }
  seq->length = length;
  seq->degree = n;
  return true;
}

// Sign changes along the sequence's values at one point (zeros skipped).
CASHASH_HOST_DEVICE inline int SignChanges(const double* values, int length) {
  int count = 0;
  double previous = 0;
  for (int k = 0; k < length; ++k) {
    const double value = values[k];
    if (value == 0) continue;
    if (previous != 0 && (value < 0) != (previous < 0)) ++count;
    previous = value;
  }
  return count;
}

// Sign changes of the sequence at t, by one thread.
CASHASH_HOST_DEVICE inline int SturmVariations(const SturmSequence& seq, double t) {
  double values[kMaxSturmLength];
  for (int k = 0; k < seq.length; ++k) values[k] = Horner(seq.S[k], seq.deg[k], t);
  return SignChanges(values, seq.length);
}

// Where one root lies: polish it in [lo, hi], or take lo as it is (an
// interval narrower than the working precision, or the split budget spent).
struct RootInterval {
  double lo, hi;
  bool polish;
};

// Splits [-bound, bound] (Fujiwara's bound on the roots' magnitude) until
// each interval holds one root, depth first, the upper half first; a
// cluster narrower than the working precision counts once. `variations(t)`
// must return SturmVariations(seq, t). Returns the number of intervals, in
// the order the roots are reported.
template <typename Variations>
CASHASH_HOST_DEVICE inline int IsolateRoots(const SturmSequence& seq, Variations variations, RootInterval* out) {
  const int n = seq.degree;
  double bound = 0;
  for (int i = 1; i <= n; ++i) {
    double a = fabs(seq.S[0][n - i]);
    if (i == n) a *= 0.5;
    bound = fmax(bound, pow(a, 1.0 / i));
  }
  bound = 2.0 * bound * 1.0001 + 1e-12;
  struct Interval {
    double lo, hi;
    int v_lo, v_hi;
  };
  Interval stack[12];
  int top = 0;
  stack[top++] = {-bound, bound, variations(-bound), variations(bound)};
  int num_roots = 0, splits = 0;
  while (top > 0 && num_roots < n) {
    const Interval I = stack[--top];
    const int count = I.v_lo - I.v_hi;
    if (count <= 0) continue;
    if (count == 1) {
      out[num_roots++] = {I.lo, I.hi, true};
      continue;
    }
    const double mid = 0.5 * (I.lo + I.hi);
    if (I.hi - I.lo <= 1e-13 * fmax(1.0, fabs(mid)) || ++splits > 800 || top + 2 > 12) {
      out[num_roots++] = {mid, mid, false};
      continue;
    }
    const int v_mid = variations(mid);
    if (v_mid - I.v_hi > 0) stack[top++] = {mid, I.hi, v_mid, I.v_hi};
    if (I.v_lo - v_mid > 0) stack[top++] = {I.lo, mid, I.v_lo, v_mid};
  }
  return num_roots;
}

// The root an interval of IsolateRoots stands for.
CASHASH_HOST_DEVICE inline double RootIn(const SturmSequence& seq, const RootInterval& interval) {
  return interval.polish ? PolishRoot(seq.S[0], seq.degree, interval.lo, interval.hi) : interval.lo;
}

// Real roots of sum_{i <= degree} c[i] t^i (degree <= 10), by one thread.
CASHASH_HOST_DEVICE inline int RealRoots(const double* coefficients, int degree, double* roots) {
  SturmSequence seq;
  if (!BuildSturmSequence(coefficients, degree, &seq)) return 0;
  RootInterval intervals[kMaxDegree];
  const int num = IsolateRoots(seq, [&seq](double t) { return SturmVariations(seq, t); }, intervals);
  for (int r = 0; r < num; ++r) roots[r] = RootIn(seq, intervals[r]);
  return num;
}

}  // namespace sturm
}  // namespace cashash
