// The fit's written-out kernels (preprocess/fit_math.h) against the library forms they replace:
// the Gaussian weight against std::exp, the 6x6 solve against Eigen's LDLT.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>

#include "preprocess/fit_math.h"

namespace sa {
namespace {

TEST(FitMath, GaussianWeightIsExpWithinFourUnitsInTheLastPlace) {
  for (int i = 0; i <= 1000000; ++i) {
    const double t = i / 1e6, want = std::exp(-t);
    const double ulp = std::nextafter(want, 2.0) - want;
    ASSERT_LE(std::abs(gaussianWeight(t) - want), 4 * ulp) << "t = " << t;
  }
  EXPECT_EQ(gaussianWeight(0.5), 0.60653065971263342);
}

// Random normal equations as the fit builds them (sum of w f f^T over a quadric's monomials, the
// ridge added): the solution matches Eigen's to 1e-9 of its size, and a matrix that is not
// positive definite is refused.
TEST(FitMath, SpdSolveMatchesEigenAndRefusesIndefiniteMatrices) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1), w(0.05, 1);
  for (int trial = 0; trial < 2000; ++trial) {
    Eigen::Matrix<double, 6, 6> M = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> rhs = Eigen::Matrix<double, 6, 1>::Zero();
    const int count = 6 + trial % 40;
    for (int j = 0; j < count; ++j) {
      const double x = u(rng), y = u(rng), z = 0.1 * u(rng), wt = w(rng);
      Eigen::Matrix<double, 6, 1> f;
      f << 1, x, y, x * x, x * y, y * y;
      M += wt * f * f.transpose();
      rhs += wt * f * z;
    }
    M.diagonal().array() += 1e-9 * M.trace();
    double A[6][6], b[6], c[6];
    for (int r = 0; r < 6; ++r) {
      b[r] = rhs[r];
      for (int q = 0; q < 6; ++q) A[r][q] = q <= r ? M(r, q) : -1e300;  // only the lower triangle is read
    }
    ASSERT_TRUE(solveSpd6(A, b, c)) << "trial " << trial;
    const Eigen::Matrix<double, 6, 1> want = M.ldlt().solve(rhs);
    for (int r = 0; r < 6; ++r) EXPECT_NEAR(c[r], want[r], 1e-9 * (1 + want.norm())) << "trial " << trial << ", c" << r;
  }
  double A[6][6] = {}, b[6] = {1, 1, 1, 1, 1, 1}, c[6];
  for (int r = 0; r < 6; ++r) A[r][r] = r == 3 ? -1 : 1;  // one negative pivot
  EXPECT_FALSE(solveSpd6(A, b, c));
  A[3][3] = 0;  // singular
  EXPECT_FALSE(solveSpd6(A, b, c));
  A[3][3] = NAN;
  EXPECT_FALSE(solveSpd6(A, b, c));
}

}  // namespace
}  // namespace sa
