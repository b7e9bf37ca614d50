// GridKnn (the chunk's k-nearest-neighbour search that replaced FLANN in normal estimation)
// against brute force: the same neighbours, in the same order, on surfaces, noise, clusters with
// far outliers, duplicates, lines, fewer points than k, a cell size far off, and the raw bunny.
#include "preprocess/grid_knn.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <mutex>
#include <random>

#include "../common/test_util.h"
#include "formats/source.h"
#include "preprocess/normals.h"

namespace sa {
namespace {

// The k smallest (d2, index) of point i, brute force.
std::vector<std::pair<double, uint32_t>> brute(const std::vector<double>& pos, size_t i, int k) {
  std::vector<std::pair<double, uint32_t>> all;
  const size_t n = pos.size() / 3;
  for (size_t j = 0; j < n; ++j) {
    const double dx = pos[3 * j] - pos[3 * i], dy = pos[3 * j + 1] - pos[3 * i + 1], dz = pos[3 * j + 2] - pos[3 * i + 2];
    all.emplace_back(dx * dx + dy * dy + dz * dz, uint32_t(j));
  }
  const size_t m = std::min(all.size(), size_t(k));
  std::partial_sort(all.begin(), all.begin() + long(m), all.end());
  all.resize(m);
  return all;
}

// Every point's forEach answer (sampled: every `stride`-th) equals brute force; returns how many were checked.
size_t checkAll(const std::vector<double>& pos, double cell, int k, size_t stride = 1) {
  const GridKnn g(pos.data(), pos.size() / 3, cell);
  std::atomic<size_t> visits{0}, checked{0};
  std::mutex m;
  std::vector<std::string> bad;
  g.forEach(k, [&](size_t i, const int* ind, const double* d2, int cnt) {
    ++visits;
    if (i % stride) return;
    ++checked;
    const auto want = brute(pos, i, k);
    bool same = size_t(cnt) == want.size();
    for (int j = 0; same && j < cnt; ++j) same = uint32_t(ind[j]) == want[size_t(j)].second && d2[j] == want[size_t(j)].first;
    if (!same) {
      std::lock_guard<std::mutex> l(m);
      if (bad.size() < 5) bad.push_back("point " + std::to_string(i) + ": " + std::to_string(cnt) + " found, " +
                                        std::to_string(want.size()) + " expected or a neighbour differs");
    }
  });
  EXPECT_EQ(visits.load(), pos.size() / 3) << "every point visited once";
  for (const auto& b : bad) ADD_FAILURE() << b;
  return checked.load();
}

std::vector<double> noisySurface(size_t n, double noise, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> e(0, noise);
  std::vector<double> pos;
  for (size_t i = 0; i < n; ++i) {
    const double x = u(rng), y = u(rng);
    pos.insert(pos.end(), {x, y, 0.1 * std::sin(6 * x) * std::cos(5 * y) + e(rng)});
  }
  return pos;
}

TEST(GridKnn, NoisySurfaceMatchesBruteForce) {
  const auto pos = noisySurface(6000, 0.002, 1);
  const double spacing = 1.0 / std::sqrt(6000.0);
  for (int k : {1, 9, 24})
    for (double f : {0.2, 1.0, 4.0})  // cell far too small, as chosen, far too large
      EXPECT_GT(checkAll(pos, f * GridKnn::cellFor(spacing, k), k, 3), 0u) << "k " << k << " cell factor " << f;
}

TEST(GridKnn, ClustersOutliersDuplicatesAndLines) {
  std::mt19937_64 rng(2);
  std::normal_distribution<double> e(0, 0.01);
  std::vector<double> pos;
  for (int c = 0; c < 3; ++c)  // three tight clusters far apart
    for (int i = 0; i < 400; ++i) pos.insert(pos.end(), {10.0 * c + e(rng), e(rng), e(rng)});
  for (int i = 0; i < 6; ++i) pos.insert(pos.end(), {5.0 + 40 * i, 7.0 * i, -3.0 * i});  // lone outliers
  for (int i = 0; i < 50; ++i) pos.insert(pos.end(), {1.0, 2.0, 3.0});                  // duplicates: ties by index
  for (int i = 0; i < 300; ++i) pos.insert(pos.end(), {0.001 * i, 3.0, 0.0});            // a line
  checkAll(pos, 0.05, 24);
  checkAll(pos, 0.05, 9);
}

TEST(GridKnn, FewerPointsThanKAndDegenerateCells) {
  std::vector<double> pos = {0, 0, 0, 1, 0, 0, 0, 2, 0, 5, 5, 5};
  checkAll(pos, 0.1, 24);  // all four, sorted
  checkAll(pos, 0.0, 2);   // no cell size: the grid picks one
  checkAll(pos, 1e9, 3);   // one cell holds everything
  std::vector<double> one = {3, 4, 5};
  checkAll(one, 1.0, 5);
  const GridKnn empty(nullptr, 0, 1.0);
  size_t calls = 0;
  empty.forEach(5, [&](size_t, const int*, const double*, int) { ++calls; });
  EXPECT_EQ(calls, 0u);
}

TEST(GridKnn, HugeExtentKeepsTheGridBounded) {
  // Two points a light-year apart (in metres) and a cell of a millimetre: the cell widens.
  std::vector<double> pos = {0, 0, 0, 9.46e15, 0, 0, 1e-3, 0, 0};
  const GridKnn g(pos.data(), 3, 1e-3);
  EXPECT_GT(g.cell(), 1e-3);
  checkAll(pos, 1e-3, 2);
}

// Radius queries (the margin finder's and the normal field's): every point within r, ascending
// (or in any order when asked), from query positions inside, at the edge of and outside the
// points' extent.
// A grid renumbered in its own order answers as a grid built afresh over the points in that
// order: the same neighbours, distances, block ranks and reaches (fitSurface's neighbour grid).
TEST(GridKnn, InOrderEqualsAGridBuiltOnTheSortedPoints) {
  std::vector<double> pos = noisySurface(3000, 0.003, 11);
  for (int i = 0; i < 40; ++i) pos.insert(pos.end(), {pos[3 * size_t(i)], pos[3 * size_t(i) + 1], pos[3 * size_t(i) + 2]});  // duplicates
  const size_t n = pos.size() / 3;
  const double cell = 0.04;
  RawVector<double> src;
  std::vector<uint32_t> orig;
  const GridKnn renumbered = GridKnn(pos.data(), n, cell).inOrder(src, orig);
  ASSERT_EQ(orig.size(), n);
  ASSERT_EQ(src.size(), 3 * n);
  for (size_t k = 0; k < n; ++k)
    for (int a = 0; a < 3; ++a) ASSERT_EQ(src[3 * k + a], pos[3 * size_t(orig[k]) + a]) << "point " << k;
  std::vector<uint32_t> sortedOrig = orig;
  std::sort(sortedOrig.begin(), sortedOrig.end());
  for (size_t k = 0; k < n; ++k) ASSERT_EQ(sortedOrig[k], k) << "orig is a permutation";
  const std::vector<double> copy(src.begin(), src.end());
  const GridKnn fresh(copy.data(), n, cell);
  for (size_t k = 0; k < n; ++k) ASSERT_EQ(fresh.order()[k], k) << "the sorted points are in the fresh grid's order";
  auto answers = [&](const GridKnn& g) {
    std::vector<std::vector<std::pair<double, int>>> out(n);
    g.forEach(24, [&](size_t i, const int* ind, const double* d2, int m) {
      for (int j = 0; j < m; ++j) out[i].emplace_back(d2[j], ind[j]);
    });
    return out;
  };
  EXPECT_EQ(answers(renumbered), answers(fresh));
  std::vector<float> value(n);
  for (size_t k = 0; k < n; ++k) value[k] = float(src[3 * k + 2]);
  EXPECT_EQ(renumbered.blockRank(value.data(), 5), fresh.blockRank(value.data(), 5));
  for (size_t k = 0; k < n; k += 13) EXPECT_EQ(renumbered.blockReach(k), fresh.blockReach(k)) << "point " << k;
}

TEST(GridKnn, WithinMatchesBruteForce) {
  const auto pos = noisySurface(5000, 0.003, 3);
  const size_t n = pos.size() / 3;
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-0.2, 1.2);
  for (double cell : {0.003, 0.03, 0.5}) {
    const GridKnn g(pos.data(), n, cell);
    std::vector<std::pair<double, uint32_t>> got;
    for (int t = 0; t < 300; ++t) {
      const double q[3] = {u(rng), u(rng), 0.3 * u(rng)};
      const double r = t % 3 == 0 ? 0.01 : (t % 3 == 1 ? 0.05 : 0.2);
      g.within(q, r, got);
      std::vector<std::pair<double, uint32_t>> want;
      for (size_t j = 0; j < n; ++j) {
        const double dx = pos[3 * j] - q[0], dy = pos[3 * j + 1] - q[1], dz = pos[3 * j + 2] - q[2];
        const double d2 = dx * dx + dy * dy + dz * dz;
        if (d2 <= r * r) want.emplace_back(d2, uint32_t(j));
      }
      std::sort(want.begin(), want.end());
      ASSERT_EQ(got, want) << "cell " << cell << " query " << t << " radius " << r;
      g.within(q, r, got, false);  // unordered: the same points
      std::sort(got.begin(), got.end());
      ASSERT_EQ(got, want) << "unordered, cell " << cell << " query " << t << " radius " << r;
    }
  }
}

// blockRank's bound: for every point, the t-th smallest value over the points within
// blockReach of it (any set of its neighbours there) is at least the point's blockRank; and the
// bound is tight somewhere (it is the rank over a real block, not a loose guess).
TEST(GridKnn, BlockRankBoundsEveryNeighbourhoodWithinReach) {
  const auto pos = noisySurface(3000, 0.004, 5);
  const size_t n = pos.size() / 3;
  std::vector<float> value(n);
  std::mt19937_64 rng(6);
  std::uniform_real_distribution<float> u(0, 1);
  for (float& v : value) v = u(rng);
  for (double cell : {0.01, 0.05, 0.3}) {
    const GridKnn g(pos.data(), n, cell);
    for (size_t t : {size_t(0), size_t(11)}) {
      const RawVector<float> low = g.blockRank(value.data(), t);
      ASSERT_EQ(low.size(), n);
      size_t tight = 0, bounded = 0;
      for (size_t i = 0; i < n; i += 7) {
        const double r = std::min(g.blockReach(i), 10.0);
        std::vector<float> near;
        for (size_t j = 0; j < n; ++j) {
          const double dx = pos[3 * j] - pos[3 * i], dy = pos[3 * j + 1] - pos[3 * i + 1], dz = pos[3 * j + 2] - pos[3 * i + 2];
          if (dx * dx + dy * dy + dz * dz < r * r) near.push_back(value[j]);
        }
        if (near.size() <= t) continue;
        std::nth_element(near.begin(), near.begin() + long(t), near.end());
        ASSERT_GE(near[t], low[i]) << "point " << i << " cell " << cell << " rank " << t;
        ++bounded;
        tight += near[t] == low[i];
      }
      if (cell >= 0.05 || t == 0) {
        EXPECT_GT(bounded, 0u) << "cell " << cell << " rank " << t;  // (0.01: blocks of ~3)
      }
      if (cell >= 0.3) {
        EXPECT_GT(tight, 0u) << "a block as large as the points' extent holds them all";
      }
    }
  }
}

// fitSurface's outlier test against its definition, brute force: a point goes when its mean
// distance to its 8 nearest exceeds ratio times the median of that mean over its k - 1 nearest
// others. The cloud makes every path of the test run: a dense sheet (neighbours within the grid
// block, most points passing on the block's bound), a sparse sheet of more than a third of the
// points (neighbours beyond the block, listed during the fit up to the cap, asked for again
// beyond it), strays above both sheets, points just above the dense sheet on either side of the
// test, and a tight cluster.
std::vector<double> outlierCloud() {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> e(0, 0.002);
  std::vector<double> pos;
  for (int i = 0; i < 2200; ++i) pos.insert(pos.end(), {u(rng), u(rng), e(rng)});                  // dense
  for (int i = 0; i < 1500; ++i) pos.insert(pos.end(), {2 + 3 * u(rng), 3 * u(rng), e(rng)});      // sparse
  for (int i = 0; i < 60; ++i) pos.insert(pos.end(), {5 * u(rng), 3 * u(rng), 0.05 + 0.3 * u(rng)});  // strays
  for (int i = 0; i < 40; ++i) pos.insert(pos.end(), {1.5 + 0.001 * u(rng), 1.5, 0.001 * u(rng)});   // cluster
  for (int i = 0; i < 150; ++i)  // just above the dense sheet: about 3 times its density, either side of the test
    pos.insert(pos.end(), {0.1 + 0.8 * u(rng), 0.1 + 0.8 * u(rng), 0.04 + 0.05 * u(rng)});
  return pos;
}

TEST(GridKnn, OutlierTestMatchesItsDefinition) {
  const std::vector<double> pos = outlierCloud();
  const size_t n = pos.size() / 3;
  const int k = 24;
  std::vector<double> density(n);
  std::vector<std::vector<std::pair<double, uint32_t>>> lists(n);
  for (size_t i = 0; i < n; ++i) {
    lists[i] = brute(pos, i, k);
    double sum = 0;
    for (size_t j = 1; j < 9; ++j) sum += std::sqrt(lists[i][j].first);
    density[i] = float(sum / 8);
  }
  const double ratio = 3;
  std::vector<uint8_t> want(n, 1);
  size_t removed = 0;
  for (size_t i = 0; i < n; ++i) {
    std::vector<double> around;
    for (size_t j = 1; j < lists[i].size(); ++j) around.push_back(density[lists[i][j].second]);
    std::nth_element(around.begin(), around.begin() + long(around.size() / 2), around.end());
    if (density[i] > ratio * around[around.size() / 2]) want[i] = 0, ++removed;
  }
  ASSERT_GT(removed, 20u) << "the strays go";
  ASSERT_LT(removed, 200u) << "the sheets stay";
  SurfaceOptions so;
  so.neighbours = k;
  so.smooth = false;
  so.outlierRatio = ratio;
  std::vector<double> copy = pos;
  std::vector<float> nrm(3 * n, 0.f);
  std::vector<uint8_t> keep;
  EXPECT_EQ(fitSurface(copy.data(), n, NormalOrientation{}, so, nrm.data(), keep), removed);
  ASSERT_EQ(keep.size(), n);
  for (size_t i = 0; i < n; ++i) EXPECT_EQ(keep[i] != 0, want[i] != 0) << "point " << i;
}

// With the file's normals kept and no smoothing the quadric is not fitted: the outliers and the
// local spacings are those of the pass that fits it, and the positions and normals are the
// caller's, untouched.
TEST(GridKnn, GivenNormalsUnsmoothedKeepTheOutliersAndSpacings) {
  const std::vector<double> pos = outlierCloud();
  const size_t n = pos.size() / 3;
  std::vector<float> given(3 * n);
  for (size_t i = 0; i < n; ++i) given[3 * i + 2] = i % 2 ? 1.f : -1.f;
  auto run = [&](bool estimate, std::vector<double>& p, std::vector<float>& nrm, std::vector<float>& spacing) {
    SurfaceOptions so;
    so.estimateNormals = estimate;
    so.smooth = false;
    p = pos;
    nrm = given;
    spacing.assign(n, 0.f);
    std::vector<uint8_t> keep;
    const size_t removed = fitSurface(p.data(), n, NormalOrientation{}, so, nrm.data(), keep, spacing.data());
    EXPECT_EQ(size_t(std::count(keep.begin(), keep.end(), 0)), removed);
    return keep;
  };
  std::vector<double> pFit, pGiven;
  std::vector<float> nFit, nGiven, sFit, sGiven;
  const std::vector<uint8_t> kFit = run(true, pFit, nFit, sFit), kGiven = run(false, pGiven, nGiven, sGiven);
  EXPECT_GT(std::count(kFit.begin(), kFit.end(), 0), 20);
  EXPECT_EQ(kGiven, kFit);
  EXPECT_EQ(sGiven, sFit);
  EXPECT_GT(*std::min_element(sGiven.begin(), sGiven.end()), 0.f);
  EXPECT_EQ(pGiven, pos);
  EXPECT_EQ(nGiven, given);
  EXPECT_NE(nFit, given) << "the fitting pass estimates normals";
}

// Laid out in the grid's order (SurfaceOptions::layOut), the fit gives each point what it gives
// it in the caller's order: the same outlier flag, smoothed position, normal (signed by its
// scan's direction) and spacing, at the point's new place.
TEST(GridKnn, FitLaidOutInGridOrderGivesEachPointTheSameResults) {
  const std::vector<double> pos = outlierCloud();
  const size_t n = pos.size() / 3;
  std::vector<uint16_t> scan(n);
  for (size_t i = 0; i < n; ++i) scan[i] = uint16_t(i % 3);
  NormalOrientation orient;
  orient.towardScanner = {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0, 0, -1), Eigen::Vector3d(1, 0, 1)};
  orient.scan = scan.data();
  orient.scanStride = sizeof(uint16_t);
  SurfaceOptions so;
  std::vector<double> p0 = pos, p1 = pos;
  std::vector<float> n0(3 * n, 0.f), n1(3 * n, 0.f), s0(n), s1(n);
  std::vector<uint8_t> k0, k1;
  std::vector<uint32_t> order;
  const size_t r0 = fitSurface(p0.data(), n, orient, so, n0.data(), k0, s0.data());
  so.layOut = true;
  const size_t r1 = fitSurface(p1.data(), n, orient, so, n1.data(), k1, s1.data(), &order);
  EXPECT_EQ(r1, r0);
  ASSERT_EQ(order.size(), n);
  size_t moved = 0;
  for (size_t i = 0; i < n; ++i) {
    const size_t o = order[i];
    moved += o != i;
    ASSERT_EQ(k1[i], k0[o]) << "point " << o;
    ASSERT_EQ(s1[i], s0[o]) << "point " << o;
    for (int a = 0; a < 3; ++a) {
      ASSERT_EQ(p1[3 * i + a], p0[3 * o + a]) << "point " << o;
      ASSERT_EQ(n1[3 * i + a], n0[3 * o + a]) << "point " << o;
    }
  }
  EXPECT_GT(moved, n / 2) << "the cloud's order is not the grid's";
}

struct Collect : BatchSink {
  std::vector<double> xyz;
  Status onPoints(const PointBatch& b) override {
    for (size_t i = 0; i < b.size(); ++i) xyz.insert(xyz.end(), {b.x[i], b.y[i], b.z[i]});
    return Status::ok();
  }
};

// The ten raw bunny scans merged (overlaps, misregistration, fringes): every 97th point checked.
TEST(GridKnnReal, BunnyScansMatchBruteForce) {
  auto input = InputSet::open({test::sharedData("stanford_bunny/scans/bun.conf")});
  ASSERT_TRUE(input.isOk()) << input.status().message();
  Collect c;
  ASSERT_TRUE(input->stream(c, false).isOk());
  const Spacing s = estimateSpacing(c.xyz.data(), c.xyz.size() / 3);
  ASSERT_GT(s.area, 0);
  EXPECT_GT(checkAll(c.xyz, GridKnn::cellFor(s.area, 24), 24, 97), 3000u);
}

}  // namespace
}  // namespace sa
