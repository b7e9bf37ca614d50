#include "preprocess/pullpush.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "atlas/pack_format.h"

namespace sa {
namespace {

double analytic(double u, double v) { return 0.05 * std::sin(3 * u) * std::cos(2 * v) + 0.02 * u; }

TileSamples samples(const std::vector<double>& u, const std::vector<double>& v, const std::vector<double>& w,
                    const uint8_t* rgb = nullptr) {
  TileSamples s;
  s.u = u.data();
  s.v = v.data();
  s.w = w.data();
  s.rgb = rgb;
  s.n = u.size();
  return s;
}

SplatOptions coverageOnly(double radius) {
  SplatOptions o;
  o.coverageRadius = radius;
  return o;
}

TileGrid unitGrid(int n) {
  TileGrid g;
  g.width = g.height = n;
  g.u0 = g.v0 = -1;
  g.du = g.dv = 2.0 / n;
  g.wMin = -0.1;
  g.wMax = 0.1;
  return g;
}

// Pull-push reconstruction of a smooth analytic height function from scattered samples at
// about one sample per texel: the RMS error stays below 0.2% of the height range (0.2).
TEST(PullPush, ReconstructsAnalyticFunction) {
  const TileGrid g = unitGrid(128);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1, 1);
  const size_t n = 128 * 128;
  std::vector<double> u(n), v(n), w(n);
  for (size_t i = 0; i < n; ++i) {
    u[i] = U(rng);
    v[i] = U(rng);
    w[i] = analytic(u[i], v[i]);
  }
  TileOutput out;
  pullPushTile(g, samples(u, v, w), coverageOnly(3 * g.du), out);
  double se = 0;
  size_t cnt = 0;
  for (int j = 0; j < g.height; ++j) {
    for (int i = 0; i < g.width; ++i) {
      const uint16_t k = out.heights[size_t(j) * g.width + i];
      ASSERT_NE(k, 0) << "texel " << i << "," << j << " uncovered";
      const double uu = g.u0 + (i + 0.5) * g.du, vv = g.v0 + (j + 0.5) * g.dv;
      const double e = decodeHeight(k, g.wMin, g.wMax) - analytic(uu, vv);
      se += e * e;
      ++cnt;
    }
  }
  const double rms = std::sqrt(se / double(cnt));
  std::printf("pull-push RMS error %.3g (bound 4e-4 = 0.2%% of the 0.2 height range)\n", rms);
  EXPECT_LT(rms, 4e-4);  // stated bound: 0.2% of the height range
}

// A disk-shaped hole larger than the coverage radius stays empty; texels near samples are
// covered.
TEST(PullPush, HolesLargerThanThresholdStayEmpty) {
  const TileGrid g = unitGrid(100);
  std::vector<double> u, v, w;
  for (int j = 0; j < 200; ++j) {
    for (int i = 0; i < 200; ++i) {
      const double uu = -1 + (i + 0.5) * 0.01, vv = -1 + (j + 0.5) * 0.01;
      if (uu * uu + vv * vv < 0.3 * 0.3) continue;  // hole of radius 0.3 = 15 texels
      u.push_back(uu);
      v.push_back(vv);
      w.push_back(0.01);
    }
  }
  TileOutput out;
  const double radius = 0.03;  // 1.5 texels
  pullPushTile(g, samples(u, v, w), coverageOnly(radius), out);
  for (int j = 0; j < g.height; ++j) {
    for (int i = 0; i < g.width; ++i) {
      const double uu = g.u0 + (i + 0.5) * g.du, vv = g.v0 + (j + 0.5) * g.dv;
      const double r = std::sqrt(uu * uu + vv * vv);
      const uint16_t k = out.heights[size_t(j) * g.width + i];
      if (r < 0.3 - radius - 0.01) {
        EXPECT_EQ(k, 0) << "hole texel " << i << "," << j << " filled";
      }
      if (r > 0.3 + 0.01) {
        ASSERT_NE(k, 0) << "texel " << i << "," << j;
        EXPECT_NEAR(decodeHeight(k, g.wMin, g.wMax), 0.01, 1e-5);
      }
    }
  }
}

// Scan rows whose coverage disks leave a crack one texel wide between them (rows 4 texels
// apart, radius 1.45 texels): the crack is closed (rows of dark dashes in close-ups of merged
// statue scans). Rows 5 texels apart leave two texels open: they stay open, as does everything
// past the last row (an edge, covered on one side only).
TEST(PullPush, OneTexelCracksBetweenRowsCloseWiderGapsAndEdgesStayOpen) {
  TileGrid g;
  g.width = g.height = 40;
  g.u0 = g.v0 = 0;
  g.du = g.dv = 1;
  g.wMin = -1;
  g.wMax = 1;
  for (const int gap : {4, 5}) {
    std::vector<double> u, v, w;
    for (int row = 0; row < 5; ++row)
      for (int i = 0; i < 160; ++i) {
        u.push_back(0.125 + 0.25 * i);
        v.push_back(0.5 + gap * row);
        w.push_back(0);
      }
    TileOutput out;
    pullPushTile(g, samples(u, v, w), coverageOnly(1.45), out);
    auto covered = [&](int j) {  // every texel of row j
      for (int i = 0; i < g.width; ++i)
        if (out.heights[size_t(j) * g.width + i] == 0) return false;
      return true;
    };
    for (int j = 0; j <= 4 * gap + 1; ++j) {
      const int offset = j % gap;  // texel row j's distance past the last sample row below it
      const bool between = offset >= 2 && offset <= gap - 2;
      if (!between) EXPECT_TRUE(covered(j)) << "gap " << gap << ", texel row " << j;
      else if (gap == 4) EXPECT_TRUE(covered(j)) << "one-texel crack at texel row " << j << " left open";
      else EXPECT_FALSE(covered(j)) << "two-texel gap at texel row " << j << " closed";
    }
    EXPECT_FALSE(covered(4 * gap + 3)) << "past the last row: an edge";
  }
}

// Randomly scattered samples (a Poisson scatter, as a survey's returns) leave gaps inside the
// tile where no sample falls within the coverage radius. With gapReach they close; a real hole
// (radius 12 texels) keeps its inside open, and the part of the tile beyond the scan's edge
// and a notch the scan left at the tile's border (both connected to the border) stay uncovered.
TEST(PullPush, SmallGapsCloseRealHolesAndEdgesStayOpen) {
  TileGrid g = unitGrid(128);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> U(-1, 1);
  std::vector<double> u, v, w;
  const double hole = 24 * g.du / 2;  // radius 12 texels, centred at (-0.4, 0)
  while (u.size() < 5000) {
    const double uu = U(rng), vv = U(rng);
    if (uu > 0.3 || std::hypot(uu + 0.4, vv) < hole) continue;  // the scan ends at u = 0.3
    if (vv > 0.7 && std::abs(uu + 0.5) < 2 * g.du) continue;  // a notch 4 texels wide from the border
    u.push_back(uu);
    v.push_back(vv);
    w.push_back(analytic(uu, vv));
  }
  // About one sample per 2 texels over the scanned part: coverage radius 1.3 texels.
  SplatOptions o = coverageOnly(1.3 * g.du);
  auto gapsAwayFromHoleAndEdge = [&](const TileOutput& out, size_t& holeCovered, size_t& beyondEdge) {
    size_t gaps = 0;
    holeCovered = beyondEdge = 0;
    for (int j = 3; j < g.height - 3; ++j)
      for (int i = 3; i < g.width - 3; ++i) {
        const double uu = g.u0 + (i + 0.5) * g.du, vv = g.v0 + (j + 0.5) * g.dv;
        const bool on = out.heights[size_t(j) * g.width + i] != 0;
        const double r = std::hypot(uu + 0.4, vv);
        if (uu > 0.3 + 2 * o.coverageRadius || (vv > 0.7 + 2 * o.coverageRadius && std::abs(uu + 0.5) < g.du))
          beyondEdge += on;
        else if (r < hole - 4 * o.coverageRadius) holeCovered += on;
        else if (uu < 0.3 - 2 * o.coverageRadius && r > hole + 2 * o.coverageRadius &&
                 !(vv > 0.7 - 2 * o.coverageRadius && std::abs(uu + 0.5) < 2 * g.du + 2 * o.coverageRadius))
          gaps += !on;
      }
    return gaps;
  };
  TileOutput open, closed;
  pullPushTile(g, samples(u, v, w), o, open);
  o.gapReach = 2 * o.coverageRadius;
  pullPushTile(g, samples(u, v, w), o, closed);
  size_t holeOpen, edgeOpen, holeClosed, edgeClosed;
  const size_t gapsOpen = gapsAwayFromHoleAndEdge(open, holeOpen, edgeOpen);
  const size_t gapsClosed = gapsAwayFromHoleAndEdge(closed, holeClosed, edgeClosed);
  std::printf("gaps in the scanned part: %zu without gapReach, %zu with\n", gapsOpen, gapsClosed);
  EXPECT_GT(gapsOpen, 20u) << "the scatter should leave gaps for this test to mean anything";
  EXPECT_EQ(gapsClosed, 0u);
  EXPECT_EQ(holeOpen, 0u);
  EXPECT_EQ(holeClosed, 0u) << "the real hole's inside was covered";
  EXPECT_EQ(edgeOpen, 0u);
  EXPECT_EQ(edgeClosed, 0u) << "surface grew past the scan's edge";
  // What was closed is the surface between the samples: heights as accurate as the covered ones.
  double worst = 0;
  for (size_t t = 0; t < closed.heights.size(); ++t) {
    if (!closed.heights[t] || open.heights[t]) continue;
    const int i = int(t % g.width), j = int(t / g.width);
    const double uu = g.u0 + (i + 0.5) * g.du, vv = g.v0 + (j + 0.5) * g.dv;
    worst = std::max(worst, std::abs(decodeHeight(closed.heights[t], closed.wMin, closed.wMax) - analytic(uu, vv)));
  }
  EXPECT_LT(worst, 0.01) << "a closed gap's height is off (range 0.2)";
}

TEST(PullPush, ColoursFollowSamples) {
  const TileGrid g = unitGrid(8);
  std::vector<double> u, v, w;
  std::vector<uint8_t> rgb;
  for (int j = 0; j < 32; ++j)
    for (int i = 0; i < 32; ++i) {
      u.push_back(-1 + (i + 0.5) / 16);
      v.push_back(-1 + (j + 0.5) / 16);
      w.push_back(0);
      rgb.insert(rgb.end(), {200, 100, 50});
    }
  TileOutput out;
  pullPushTile(g, samples(u, v, w, rgb.data()), coverageOnly(0.3), out);
  ASSERT_EQ(out.rgba.size(), 8u * 8 * 4);
  EXPECT_EQ(out.rgba[0], 200);
  EXPECT_EQ(out.rgba[1], 100);
  EXPECT_EQ(out.rgba[2], 50);
  EXPECT_EQ(out.rgba[3], 255);
}

// The triangle path: a rasterized plane is exact at every covered texel centre (inside the
// triangle, and continued over the texels it touches within half a texel diagonal, so coverage
// has no sub-texel gaps at the edges of the triangles a cell holds); texels farther out stay empty.
// Heights rounded for the page coder (PackOptions::heightStep): codes on a power-of-two step
// whose world size is at most the asked one, every height within half of it (a whole step at
// the range's top, rounded down to stay inside), holes still holes, covered texels covered.
TEST(PullPush, RoundedHeightsStayWithinHalfTheirStep) {
  std::mt19937 rng(5);
  for (double range : {0.001, 0.2, 7.0, 300.0}) {
    TileOutput t;
    t.wMin = -range / 3;
    t.wMax = t.wMin + range;
    t.heights.resize(4096);
    for (size_t k = 0; k < t.heights.size(); ++k) t.heights[k] = k % 17 == 0 ? 0 : uint16_t(1 + rng() % 65535);
    t.heights[1] = 65535;  // the top code
    t.heights[2] = 1;      // the bottom
    const std::vector<uint16_t> before = t.heights;
    const double maxStep = 0.01;
    const uint32_t m = roundHeights(t, maxStep);
    const double codeSize = range / 65534;
    EXPECT_LE(m * codeSize, maxStep * (1 + 1e-12));
    if (m > 1 && m < 32768) {
      EXPECT_GT(2 * m * codeSize, maxStep) << "the largest such step";
    }
    for (size_t k = 0; k < t.heights.size(); ++k) {
      ASSERT_EQ(before[k] == 0, t.heights[k] == 0);
      if (!before[k]) continue;
      ASSERT_EQ((t.heights[k] - 1) % m, 0u);
      const double moved = std::abs(decodeHeight(t.heights[k], t.wMin, t.wMax) - decodeHeight(before[k], t.wMin, t.wMax));
      ASSERT_LE(moved, (before[k] > 65534 - m ? 1.0 : 0.5) * m * codeSize * (1 + 1e-9)) << "range " << range;
    }
  }
  TileOutput flat;
  flat.wMin = flat.wMax = 1;
  flat.heights = {0, 5, 9};
  EXPECT_EQ(roundHeights(flat, 0.1), 1u) << "an empty range keeps its codes";
  EXPECT_EQ(flat.heights[1], 5);
}

TEST(Raster, TriangleHeightsAreExact) {
  const TileGrid g = unitGrid(64);
  auto plane = [](double u, double v) { return 0.03 * u - 0.02 * v + 0.01; };
  const double tri[9] = {-0.9, -0.9, plane(-0.9, -0.9), 0.9, -0.9, plane(0.9, -0.9), -0.9, 0.9, plane(-0.9, 0.9)};
  TileOutput out;
  rasterizeTile(g, tri, 1, 0.01, 0.0, nullptr, out);
  size_t covered = 0;
  for (int j = 0; j < g.height; ++j)
    for (int i = 0; i < g.width; ++i) {
      const double uu = g.u0 + (i + 0.5) * g.du, vv = g.v0 + (j + 0.5) * g.dv;
      const uint16_t k = out.heights[size_t(j) * g.width + i];
      const bool inside = uu >= -0.9 && vv >= -0.9 && uu + vv <= 0.0;
      if (k) {
        ++covered;
        EXPECT_NEAR(decodeHeight(k, g.wMin, g.wMax), plane(uu, vv), 2e-6);
      }
      if (inside && uu > -0.88 && vv > -0.88 && uu + vv < -0.02) {
        EXPECT_NE(k, 0);
      }
      const double reach = 0.75 * g.du;  // half a texel diagonal, and a little
      if (!inside && (uu < -0.9 - reach || vv < -0.9 - reach || uu + vv > reach * std::sqrt(2.0))) {
        EXPECT_EQ(k, 0);
      }
    }
  EXPECT_GT(covered, 700u);
}

}  // namespace
}  // namespace sa
