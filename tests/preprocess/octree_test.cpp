#include "preprocess/octree.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <map>
#include <random>

#include "../common/test_util.h"

namespace sa {
namespace {

struct Cloud {
  std::vector<double> pos;
  std::vector<float> nrm;
  void add(const Eigen::Vector3d& p, const Eigen::Vector3d& n) {
    pos.insert(pos.end(), {p.x(), p.y(), p.z()});
    nrm.insert(nrm.end(), {float(n.x()), float(n.y()), float(n.z())});
  }
  std::vector<uint32_t> indices() const {
    std::vector<uint32_t> idx(pos.size() / 3);
    for (uint32_t i = 0; i < idx.size(); ++i) idx[i] = i;
    return idx;
  }
};

std::vector<OctreeCell> build(const Cloud& c, OctreeParams p = {}) {
  auto idx = c.indices();
  std::vector<OctreeCell> cells;
  buildOctree(c.pos.data(), c.nrm.data(), idx, Eigen::Vector3d::Constant(-1), 2.0, 0, p, cells);
  return cells;
}

bool finiteFit(const PlaneFit& f) {
  return f.centroid.allFinite() && f.u.allFinite() && f.v.allFinite() && f.w.allFinite() &&
         std::abs(f.w.norm() - 1) < 1e-9 && std::abs(f.u.dot(f.w)) < 1e-9 && std::abs(f.v.dot(f.w)) < 1e-9;
}

// 20000 random points of the plane through the origin with normal n, their normals n.
Cloud tiltedPlane(const Eigen::Vector3d& n, unsigned seed) {
  Cloud c;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(-0.9, 0.9);
  for (int i = 0; i < 20000; ++i) {
    Eigen::Vector3d p(U(rng), U(rng), 0);
    p.z() = -(n.x() * p.x() + n.y() * p.y()) / n.z();
    c.add(p, n);
  }
  return c;
}

// The parallel partition must give std::partition's order exactly (octrees, and so packs, stay
// the same): small ranges, ranges past the parallel threshold, every index on one side, and
// shuffled indices over points in random order.
TEST(Octree, PartitionBelowIsStdPartitionsOrder) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  for (size_t n : {size_t(0), size_t(1), size_t(1000), size_t(65535), size_t(65536), size_t(200001), size_t(1000003)}) {
    std::vector<double> pos(3 * n);
    for (double& v : pos) v = u(rng);
    std::vector<uint32_t> idx(n);
    for (uint32_t i = 0; i < n; ++i) idx[i] = i;
    std::shuffle(idx.begin(), idx.end(), rng);
    for (double mid : {-1.0, 0.3, 0.5, 2.0})
      for (int axis = 0; axis < 3; ++axis) {
        std::vector<uint32_t> want = idx, got = idx;
        const auto w = std::partition(want.begin(), want.end(), [&](uint32_t i) { return pos[3 * i + axis] < mid; }) - want.begin();
        const auto g = partitionBelow(got.data(), got.data() + n, pos.data(), axis, mid) - got.data();
        ASSERT_EQ(w, g) << n << " points, axis " << axis << ", mid " << mid;
        ASSERT_EQ(want, got) << n << " points, axis " << axis << ", mid " << mid;
      }
  }
}

// countLayeredBins against its definition (points grouped by square bin of the fit's plane, a
// bin layered when its sorted heights leave a gap wider than `gap`, counted up to `enough`), on
// sheets with a second layer over part of them, in a tilted frame: bins of one point, of two,
// of many; boxes of few bins per point (counted into bins) and of many (sorted).
TEST(Octree, LayeredBinsAreCountedAsDefined) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> u(0, 1);
  PlaneFit f;
  f.centroid = Eigen::Vector3d(0.3, -0.2, 0.1);
  f.u = Eigen::Vector3d(1, 1, 0).normalized();
  f.w = Eigen::Vector3d(0.2, -0.2, 1).normalized();
  f.v = f.w.cross(f.u).normalized();
  f.u = f.v.cross(f.w);
  int trials = 0, counted = 0, capped = 0;
  for (size_t n : {size_t(2), size_t(3), size_t(17), size_t(200), size_t(3000)})
    for (double bin : {0.01, 0.05, 0.3})
      for (int spread : {1, 20}) {
        std::vector<double> pos;
        for (size_t i = 0; i < n; ++i) {
          const double a = spread * u(rng), b = u(rng), over = (a < 0.5 * spread && u(rng) < 0.4) ? 0.2 : 0.0;
          const Eigen::Vector3d p = f.centroid + f.u * a + f.v * b + f.w * (0.02 * u(rng) + over);
          pos.insert(pos.end(), p.data(), p.data() + 3);
        }
        std::vector<uint32_t> idx(n);
        for (uint32_t i = 0; i < n; ++i) idx[i] = i;
        std::shuffle(idx.begin(), idx.end(), rng);
        std::map<std::pair<int64_t, int64_t>, std::vector<double>> bins;
        for (uint32_t i : idx) {
          const Eigen::Vector3d d = Eigen::Vector3d(&pos[3 * i]) - f.centroid;
          bins[{int64_t(std::floor(d.dot(f.u) / bin)), int64_t(std::floor(d.dot(f.v) / bin))}].push_back(d.dot(f.w));
        }
        for (double gap : {0.05, 0.15}) {
          uint32_t want = 0;
          for (auto& [k, hs] : bins) {
            std::sort(hs.begin(), hs.end());
            for (size_t j = 1; j < hs.size(); ++j)
              if (hs[j] - hs[j - 1] > gap) {
                ++want;
                break;
              }
          }
          for (uint32_t enough : {1u, 3u, 1000000u}) {
            const uint32_t got = countLayeredBins(pos.data(), idx.data(), n, f, bin, gap, enough);
            ASSERT_EQ(got, std::min(want, enough)) << n << " points, bin " << bin << ", spread " << spread << ", gap " << gap;
            ++trials;
            counted += want > 0;
            capped += want > enough;
          }
        }
      }
  std::printf("%d trials, %d with layered bins, %d capped\n", trials, counted, capped);
  EXPECT_GT(counted, trials / 4);
  EXPECT_GT(capped, 0);
}

TEST(Octree, TiltedPlaneIsOneCell) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.3, 0.2, 1).normalized();
  const Cloud c = tiltedPlane(n, 1);
  auto cells = build(c);
  ASSERT_EQ(cells.size(), 1u);
  EXPECT_TRUE(cells[0].fit.heightField);
  EXPECT_NEAR(std::abs(cells[0].fit.w.dot(n)), 1.0, 1e-9);
  EXPECT_GT(cells[0].fit.w.dot(n), 0);  // W agrees with the normals
}

// maxLeafPoints bounds a tile's memory: a plane that is one height field is split until no
// cell holds more points, and every piece is still a height field.
TEST(Octree, HeightFieldsLargerThanMaxLeafPointsAreSplit) {
  const Cloud c = tiltedPlane(Eigen::Vector3d(0.3, 0.2, 1).normalized(), 2);
  OctreeParams p;
  p.maxLeafPoints = 3000;
  const auto cells = build(c, p);
  EXPECT_GE(cells.size(), 20000u / 3000u);
  size_t total = 0;
  for (const auto& cell : cells) {
    EXPECT_LE(cell.count, p.maxLeafPoints);
    EXPECT_TRUE(cell.fit.heightField);
    total += cell.count;
  }
  EXPECT_EQ(total, 20000u);
  EXPECT_EQ(build(c).size(), 1u) << "no limit: one cell";
}

TEST(Octree, SphereSplitsIntoAtLeastEightHeightFields) {
  Cloud c;
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(50000, 0.9, Eigen::Vector3d::Zero(), pts, nrm);
  for (size_t i = 0; i < pts.size(); ++i) c.add(pts[i], nrm[i]);
  OctreeParams p;
  p.outlierFraction = 0;  // exact normals: the paper's strict test
  auto cells = build(c, p);
  EXPECT_GE(cells.size(), 8u);
  size_t total = 0;
  for (const auto& cell : cells) {
    EXPECT_TRUE(cell.fit.heightField);
    EXPECT_FALSE(cell.forced);
    total += cell.count;
  }
  EXPECT_EQ(total, pts.size());
}

TEST(Octree, DegenerateCellsNeverProduceNaN) {
  const float n[3] = {0, 0, 1};
  // Single point.
  {
    double p[3] = {0.1, 0.2, 0.3};
    uint32_t idx = 0;
    PlaneFit f = fitPlane(p, n, &idx, 1, 0.0);
    EXPECT_TRUE(finiteFit(f));
    EXPECT_TRUE(f.degenerate);
  }
  // Duplicates.
  {
    std::vector<double> p;
    std::vector<float> nn;
    std::vector<uint32_t> idx;
    for (uint32_t i = 0; i < 50; ++i) {
      p.insert(p.end(), {1e6 + 0.5, 5e6 + 0.25, 100.0});
      nn.insert(nn.end(), {0, 1, 0});
      idx.push_back(i);
    }
    PlaneFit f = fitPlane(p.data(), nn.data(), idx.data(), idx.size(), 0.0);
    EXPECT_TRUE(finiteFit(f));
    EXPECT_NEAR(f.w.y(), 1.0, 1e-9);
  }
  // Collinear: W must be orthogonal to the line and close to the normals.
  {
    std::vector<double> p;
    std::vector<float> nn;
    std::vector<uint32_t> idx;
    for (uint32_t i = 0; i < 50; ++i) {
      p.insert(p.end(), {i * 0.01, i * 0.01, 0.0});
      nn.insert(nn.end(), {0, 0, 1});
      idx.push_back(i);
    }
    PlaneFit f = fitPlane(p.data(), nn.data(), idx.data(), idx.size(), 0.0);
    EXPECT_TRUE(finiteFit(f));
    EXPECT_TRUE(f.degenerate);
    EXPECT_NEAR(f.w.dot(Eigen::Vector3d(1, 1, 0).normalized()), 0.0, 1e-9);
    EXPECT_NEAR(f.w.z(), 1.0, 1e-9);
  }
  // Two points, and points without normals (zero vectors).
  {
    double p[6] = {0, 0, 0, 1, 1, 1};
    float zn[6] = {0, 0, 0, 0, 0, 0};
    uint32_t idx[2] = {0, 1};
    PlaneFit f = fitPlane(p, zn, idx, 2, 0.0);
    EXPECT_TRUE(finiteFit(f));
  }
}

TEST(Octree, PointsOnSplitPlanesAreKeptOnce) {
  Cloud c;
  for (int i = 0; i < 200; ++i) {
    c.add(Eigen::Vector3d(0, 0, i * 0.004 - 0.4), Eigen::Vector3d(1, 0, 0));   // on x = 0 and y = 0 planes
    c.add(Eigen::Vector3d(0.5, 0, i * 0.004 - 0.4), Eigen::Vector3d(-1, 0, 0)); // facing the other way
  }
  auto cells = build(c);
  size_t total = 0;
  for (const auto& cell : cells) {
    total += cell.count;
    EXPECT_TRUE(finiteFit(cell.fit));
  }
  EXPECT_EQ(total, 400u);
  EXPECT_GE(cells.size(), 2u);  // opposite normals cannot share a height field
}

}  // namespace
}  // namespace sa
