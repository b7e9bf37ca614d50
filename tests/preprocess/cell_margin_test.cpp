// MarginFinder::tileField (the chunk's points near a tile gathered once, each adding its weight
// to the texels it reaches) against normalField (a grid query per texel): the same normals to the bit, on a
// tilted, curved, noisy sheet with a second layer just over a radius above it and texels past
// the points' edge.
#include "preprocess/cell_margin.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
#include <algorithm>
#include <random>

namespace sa {
namespace {

TEST(MarginFinder, TileFieldEqualsTheFieldQueriedPerTexel) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> e(0, 0.003);
  // The frame: tilted about two axes, away from the origin.
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(0.6, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(-0.4, Eigen::Vector3d::UnitY())).toRotationMatrix();
  const Eigen::Vector3d O(120.5, -40.25, 7.0), U = R.col(0), V = R.col(1), W = R.col(2);
  auto height = [](double a, double b) { return 0.08 * std::sin(5 * a) * std::cos(4 * b); };
  std::vector<double> pos;
  std::vector<float> nrm;
  auto add = [&](double a, double b, double h, const Eigen::Vector3d& n) {
    const Eigen::Vector3d p = O + U * a + V * b + W * h;
    pos.insert(pos.end(), {p.x(), p.y(), p.z()});
    const Eigen::Vector3d nn = n.normalized();
    nrm.insert(nrm.end(), {float(nn.x()), float(nn.y()), float(nn.z())});
  };
  for (int i = 0; i < 6000; ++i) {
    const double a = 1.2 * u(rng) - 0.1, b = 1.2 * u(rng) - 0.1;
    add(a, b, height(a, b) + e(rng), W + 0.3 * (u(rng) - 0.5) * U + 0.3 * (u(rng) - 0.5) * V);
  }
  const double radius = 0.04;
  for (int i = 0; i < 800; ++i) {  // a layer just over a radius above, facing the other way in part
    const double a = u(rng), b = u(rng);
    add(a, b, height(a, b) + 1.2 * radius, i % 3 ? W : Eigen::Vector3d(-W));
  }
  const size_t n = pos.size() / 3;
  const MarginFinder mf(pos.data(), nrm.data(), n);
  // Texels of a 0.02 grid over [0, 1]^2 on the sheet (every third skipped: uncovered).
  const int width = 50, height_ = 50;
  const double du = 0.02, dv = 0.02;
  std::vector<size_t> texels;
  std::vector<double> xyz;
  std::vector<float> hints;
  for (int j = 0; j < height_; ++j)
    for (int i = 0; i < width; ++i) {
      if ((i + 2 * j) % 3 == 0) continue;
      const double a = (i + 0.5) * du, b = (j + 0.5) * dv;
      const Eigen::Vector3d x = O + U * a + V * b + W * height(a, b);
      texels.push_back(size_t(j) * width + size_t(i));
      xyz.insert(xyz.end(), {x.x(), x.y(), x.z()});
      hints.insert(hints.end(), {float(W.x()), float(W.y()), float(W.z())});
    }
  const size_t m = texels.size();
  std::vector<float> plain(3 * m), tiled(3 * m);
  mf.normalField(xyz.data(), hints.data(), m, radius, plain.data());
  MarginFinder::TileTexels grid(size_t(width) * height_);
  for (size_t k = 0; k < m; ++k) {
    const size_t t = texels[k];
    grid.x[t] = xyz[3 * k], grid.y[t] = xyz[3 * k + 1], grid.z[t] = xyz[3 * k + 2];
    grid.hx[t] = hints[3 * k], grid.hy[t] = hints[3 * k + 1], grid.hz[t] = hints[3 * k + 2];
  }
  mf.tileField({O, U, V, 0.0, 0.0, du, dv, width, height_}, radius, grid);
  for (size_t k = 0; k < m; ++k) {
    const size_t t = texels[k];
    tiled[3 * k] = grid.hx[t], tiled[3 * k + 1] = grid.hy[t], tiled[3 * k + 2] = grid.hz[t];
  }
  EXPECT_EQ(std::memcmp(plain.data(), tiled.data(), plain.size() * sizeof(float)), 0);
  size_t moved = 0, differ = 0;
  for (size_t k = 0; k < 3 * m; ++k) {
    moved += plain[k] != hints[k];
    differ += plain[k] != tiled[k];
  }
  EXPECT_EQ(differ, 0u);
  EXPECT_GT(moved, m) << "the field is not just the hints";
}

// The field's sums are exact: the same points in another order (another grid, another bin
// order) give the same bits, and the normal is the weighted mean a plain double sum gives.
TEST(MarginFinder, FieldIsTheWeightedMeanInAnyOrder) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<double> pos;
  std::vector<float> nrm;
  for (int i = 0; i < 4000; ++i) {
    const double a = u(rng), b = u(rng);
    pos.insert(pos.end(), {a, b, 0.05 * std::sin(6 * a + 3 * b)});
    Eigen::Vector3d n(0.4 * (u(rng) - 0.5), 0.4 * (u(rng) - 0.5), i % 7 ? 1.0 : -1.0);
    n.normalize();
    nrm.insert(nrm.end(), {float(n.x()), float(n.y()), float(n.z())});
  }
  const size_t n = pos.size() / 3;
  std::vector<uint32_t> perm(n);
  for (uint32_t i = 0; i < n; ++i) perm[i] = i;
  std::shuffle(perm.begin(), perm.end(), rng);
  std::vector<double> pos2(pos.size());
  std::vector<float> nrm2(nrm.size());
  for (size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) pos2[3 * i + a] = pos[3 * perm[i] + a], nrm2[3 * i + a] = nrm[3 * perm[i] + a];
  std::vector<double> xyz;
  std::vector<float> hints;
  for (int i = 0; i < 300; ++i) {
    const double a = u(rng), b = u(rng);
    xyz.insert(xyz.end(), {a, b, 0.05 * std::sin(6 * a + 3 * b)});
    hints.insert(hints.end(), {0.f, 0.f, 1.f});
  }
  const size_t m = xyz.size() / 3;
  const double radius = 0.05;
  std::vector<float> one(3 * m), two(3 * m);
  MarginFinder(pos.data(), nrm.data(), n).normalField(xyz.data(), hints.data(), m, radius, one.data());
  MarginFinder(pos2.data(), nrm2.data(), n, 0.013).normalField(xyz.data(), hints.data(), m, radius, two.data());
  EXPECT_EQ(std::memcmp(one.data(), two.data(), one.size() * sizeof(float)), 0);
  double worst = 0;
  size_t moved = 0;
  for (size_t k = 0; k < m; ++k) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (size_t j = 0; j < n; ++j) {
      const Eigen::Vector3d d = Eigen::Vector3d(&pos[3 * j]) - Eigen::Vector3d(&xyz[3 * k]);
      const Eigen::Vector3d nn(nrm[3 * j], nrm[3 * j + 1], nrm[3 * j + 2]);
      const double q = 1 - d.squaredNorm() / (radius * radius);
      if (q > 0 && nn.z() > 0.5) sum += q * q * nn;
    }
    ASSERT_GT(sum.norm(), 0);
    sum.normalize();
    worst = std::max(worst, (sum - Eigen::Vector3d(one[3 * k], one[3 * k + 1], one[3 * k + 2]).cast<double>()).norm());
    moved += std::abs(one[3 * k + 2] - 1.f) > 1e-4f;
  }
  EXPECT_LT(worst, 1e-6);
  EXPECT_GT(moved, m / 2) << "the field is not just the hints";
}

}  // namespace
}  // namespace sa
