// Two small numeric kernels of the per-point surface fit (preprocess/normals.cpp), written out
// so that the fit calls no library for them, and tested alone (tests/preprocess/fit_math_test.cpp).
#pragma once
#include <array>
#include <cmath>
#include <cstddef>

namespace sa {

// 1 / n! for n = 0 .. 14 (each n! exact in a double, so each entry is correctly rounded).
inline constexpr std::array<double, 15> kInverseFactorial = [] {
  std::array<double, 15> c{};
  double f = 1;
  for (int n = 0; n < 15; ++n) {
    if (n > 0) f *= n;
    c[size_t(n)] = 1 / f;
  }
  return c;
}();

// exp(-t) for t in [0, 1] (a neighbour's d^2 / h^2, h the farthest's distance) to a few units in
// the last place: exp(-1/2) e^s for s = 1/2 - t, e^s by its Taylor series to s^14 (the remainder
// is under 0.5^15 / 15! = 2.3e-17). No call, so a loop of weights vectorizes: std::exp was a
// sixth of the fit's instructions.
inline double gaussianWeight(double t) {
  const double s = 0.5 - t;
  double e = kInverseFactorial[14];
  for (int n = 13; n >= 0; --n) e = e * s + kInverseFactorial[size_t(n)];
  return 0.60653065971263342 * e;  // exp(-1/2)
}

// Solves A c = b for a symmetric positive definite 6x6 A given by its lower triangle, by LDL^T
// without pivoting (stable for such a matrix: every pivot is positive). False where a pivot is
// not positive or the solution not finite. Written out for the quadric's normal equations, which
// the ridge keeps positive definite: the functions of Eigen's pivoting LDLT were 3 % of a pack's
// instructions and 5 % of its mispredicted branches (cachegrind).
inline bool solveSpd6(const double A[6][6], const double b[6], double c[6]) {
  double L[6][6], LD[6][6], D[6];  // L unit lower triangular; LD[i][k] = L[i][k] D[k]
  for (int j = 0; j < 6; ++j) {
    double d = A[j][j];
    for (int k = 0; k < j; ++k) d -= LD[j][k] * L[j][k];
    if (!(d > 0)) return false;
    D[j] = d;
    for (int i = j + 1; i < 6; ++i) {
      double v = A[i][j];
      for (int k = 0; k < j; ++k) v -= LD[i][k] * L[j][k];
      LD[i][j] = v;
      L[i][j] = v / d;
    }
  }
  double y[6];
  for (int i = 0; i < 6; ++i) {
    double v = b[i];
    for (int k = 0; k < i; ++k) v -= L[i][k] * y[k];
    y[i] = v;
  }
  for (int i = 5; i >= 0; --i) {
    double v = y[i] / D[i];
    for (int k = i + 1; k < 6; ++k) v -= L[k][i] * c[k];
    c[i] = v;
  }
  for (int i = 0; i < 6; ++i)
    if (!std::isfinite(c[i])) return false;
  return true;
}

}  // namespace sa
