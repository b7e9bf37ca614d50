// Estimated normals on a scene whose true normals are known (the synthetic survey of
// tools/terrain_scene.h: terrain, roofs, walls, 3 cm noise): the sign must match the truth on
// walls as well as on terrain and roofs (the +z cue of airborne data cannot decide walls), and a
// pack with estimated normals must give about the cells a pack with the true normals gives
// (issue "Scale": count within 1.5x, forced fraction within +5 points).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>

#include "../common/test_util.h"
#include "atlas/pack_file.h"
#include "formats/source.h"
#include "preprocess/normals.h"
#include "preprocess/pipeline.h"
#include "tools/terrain_scene.h"

namespace sa {
namespace {

struct Scene {
  std::vector<double> pos;
  std::vector<float> truth;
  std::vector<bool> wall;
};

// n points of the survey, restricted to a square of `side` metres (density as for `total` points).
Scene survey(size_t n, double side) {
  const gen::Scene s;
  std::mt19937_64 rng(5);
  Scene out;
  while (out.pos.size() < 3 * n) {
    const gen::Point p = s.sample(rng);
    if (p.x > side || p.y > side) continue;
    out.pos.insert(out.pos.end(), {p.x, p.y, p.z});
    out.truth.insert(out.truth.end(), {p.n[0], p.n[1], p.n[2]});
    out.wall.push_back(p.n[2] == 0);
  }
  return out;
}

TEST(NormalsScene, EstimatedSignsMatchTheTruthOnWallsRoofsAndTerrain) {
  // 150 m x 150 m at the density of 2 M points over the full 1 km square (0.36 m spacing).
  const Scene sc = survey(45000, 150);
  const size_t n = sc.pos.size() / 3;
  std::vector<float> nrm(3 * n, 0.f);
  NormalOrientation orient;
  orient.towardScanner = {Eigen::Vector3d::UnitZ()};
  std::vector<uint16_t> scan(n, 0);
  orient.scan = scan.data();
  orient.scanStride = sizeof(uint16_t);
  estimateNormals(sc.pos.data(), n, 24, orient, nrm.data());
  size_t walls = 0, wallsRight = 0, other = 0, otherRight = 0, unknown = 0;
  std::vector<double> angle;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f e(&nrm[3 * i]), t(&sc.truth[3 * i]);
    if (e.squaredNorm() > 0) angle.push_back(std::acos(std::clamp(double(e.dot(t)), -1.0, 1.0)) * 180 / M_PI);
    if (e.squaredNorm() == 0) {
      ++unknown;
      continue;
    }
    // Points at an edge (roof rim, wall foot) have a blended normal; count the sign where the
    // estimate is within 60 degrees of either the truth or its opposite.
    if (std::abs(e.dot(t)) < 0.5) continue;
    (sc.wall[i] ? walls : other)++;
    if (e.dot(t) > 0) (sc.wall[i] ? wallsRight : otherRight)++;
  }
  std::printf("[normals-scene] %zu points: walls %zu signed right of %zu (%.2f %%), terrain+roofs %zu of %zu (%.2f %%), unknown %zu\n",
              n, wallsRight, walls, 100.0 * wallsRight / std::max<size_t>(walls, 1), otherRight, other,
              100.0 * otherRight / std::max<size_t>(other, 1), unknown);
  std::sort(angle.begin(), angle.end());
  auto pct = [&](double q) { return angle[size_t(q * (angle.size() - 1))]; };
  std::printf("[normals-scene] angle to the true normal: median %.2f, p90 %.2f, p99 %.2f deg\n", pct(0.5), pct(0.9), pct(0.99));
  {
    size_t big[2] = {0, 0}, cnt[2] = {0, 0};
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3f e(&nrm[3 * i]), t(&sc.truth[3 * i]);
      ++cnt[sc.wall[i]];
      if (e.dot(t) < std::cos(60 * M_PI / 180)) ++big[sc.wall[i]];
    }
    std::printf("[normals-scene] beyond 60 deg: ground+roofs %zu of %zu, walls %zu of %zu\n", big[0], cnt[0], big[1], cnt[1]);
  }
  ASSERT_GT(walls, 1000u);
  EXPECT_GE(double(wallsRight), 0.97 * double(walls));
  EXPECT_GE(double(otherRight), 0.995 * double(other));
}

PackMeta packScene(const std::string& path, const std::string& out, PackSummary& sum) {
  auto in = InputSet::open({path});
  EXPECT_TRUE(in.isOk()) << in.status().message();
  if (!in.isOk()) return {};
  EXPECT_TRUE(packInput(*in, out, PackOptions{}, nullptr, sum).isOk());
  PackReader r;
  EXPECT_TRUE(r.open(out).isOk());
  return r.meta();
}

// The same survey as LAS (no normals: estimated, oriented toward +z and then by propagation) and
// as PLY with its true normals: about the same cells.
TEST(NormalsScene, EstimatedNormalsGiveTheCellsOfTheTrueNormals) {
  test::TempDir d;
  const std::string gen = SA_GEN_TERRAIN;
  for (const char* ext : {"las", "ply"})
    ASSERT_EQ(std::system((gen + " 300000 " + d.file(std::string("s.") + ext)).c_str()), 0) << "sa_gen_terrain failed";
  PackSummary las, ply;
  packScene(d.file("s.las"), d.file("las.hfa"), las);
  packScene(d.file("s.ply"), d.file("ply.hfa"), ply);
  ASSERT_TRUE(las.normalsEstimated);
  ASSERT_FALSE(ply.normalsEstimated);
  const double fl = double(las.forcedCells) / double(las.cells), fp = double(ply.forcedCells) / double(ply.cells);
  std::printf("[normals-scene] 300000 points: estimated normals %llu cells (%.1f %% forced), true normals %llu cells (%.1f %% forced)\n",
              (unsigned long long)las.cells, 100 * fl, (unsigned long long)ply.cells, 100 * fp);
  EXPECT_LE(double(las.cells), 1.5 * double(ply.cells));
  EXPECT_GE(double(las.cells), double(ply.cells) / 1.5);
  EXPECT_LE(fl, fp + 0.05);
}

}  // namespace
}  // namespace sa
