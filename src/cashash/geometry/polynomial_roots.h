// Real roots of low-degree polynomials, for the 7-point solver.
#pragma once

namespace cashash {

// Real roots of c3 x^3 + c2 x^2 + c1 x + c0 (falls back to lower degree when
// the leading coefficients vanish). Returns the count (0 to 3) in `roots`.
int SolveCubicReal(double c3, double c2, double c1, double c0, double roots[3]);

}  // namespace cashash
