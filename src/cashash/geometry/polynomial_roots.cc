#include "cashash/geometry/polynomial_roots.h"

#include <cmath>

namespace cashash {
namespace {

int SolveQuadraticReal(double a, double b, double c, double roots[2]) {
  if (a == 0) {
    if (b == 0) return 0;
    roots[0] = -c / b;
    return 1;
  }
  const double disc = b * b - 4 * a * c;
  if (disc < 0) return 0;
  // The sign trick avoids cancellation between -b and sqrt(disc).
  const double q = -0.5 * (b + std::copysign(std::sqrt(disc), b));
  if (q == 0) {
    roots[0] = 0;
    return 1;
  }
  roots[0] = q / a;
  roots[1] = c / q;
  return 2;
}

// Two Newton steps clean up the closed-form roots' rounding.
double PolishCubicRoot(double a, double b, double c, double x) {
  for (int i = 0; i < 2; ++i) {
    const double f = ((x + a) * x + b) * x + c;
    const double df = (3 * x + 2 * a) * x + b;
    if (df == 0) break;
    x -= f / df;
  }
  return x;
}

}  // namespace

int SolveCubicReal(double c3, double c2, double c1, double c0, double roots[3]) {
  const double scale = std::fabs(c2) + std::fabs(c1) + std::fabs(c0);
  if (std::fabs(c3) <= 1e-14 * scale) return SolveQuadraticReal(c2, c1, c0, roots);
  // Monic x^3 + a x^2 + b x + c, depressed by x = t - a/3.
  const double a = c2 / c3, b = c1 / c3, c = c0 / c3;
  const double a_third = a / 3.0;
  const double p = b - a * a_third;
  const double q = 2.0 * a_third * a_third * a_third - a_third * b + c;
  const double disc = 0.25 * q * q + p * p * p / 27.0;
  int n = 0;
  if (disc > 0) {
    const double s = std::sqrt(disc);
    roots[n++] = std::cbrt(-0.5 * q + s) + std::cbrt(-0.5 * q - s) - a_third;
  } else if (p == 0) {
    roots[n++] = -a_third;
  } else {
    // Three real roots: trigonometric form.
    const double r = std::sqrt(-p / 3.0);
    const double arg = std::fmax(-1.0, std::fmin(1.0, -0.5 * q / (r * r * r)));
    const double phi = std::acos(arg) / 3.0;
    for (int k = 0; k < 3; ++k) {
      roots[n++] = 2.0 * r * std::cos(phi - 2.0 * M_PI * k / 3.0) - a_third;
    }
  }
  for (int i = 0; i < n; ++i) roots[i] = PolishCubicRoot(a, b, c, roots[i]);
  return n;
}

}  // namespace cashash
