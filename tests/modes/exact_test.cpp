// The exact mode's CPU traversal (modes/exact/exact.h), GL-free: the maximum-mipmap traversal
// against every patch along the ray (the same root solver without the pyramid), and both
// against an independent fine march over CpuRaycaster::height (the sampling rule of the shader),
// on real packs: the bunny's raw scans (holes, scan edges, stored normals) and the dragon mesh.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "atlas/raycast.h"
#include "modes/exact/exact.h"
#include "preprocess/pipeline.h"
#include "../common/test_util.h"

namespace sa {
namespace {

struct Ray {
  uint32_t cell;
  Eigen::Vector3d o, d;  // frame coordinates
  double t0, t1;
};

// Random rays through random cells: from outside the box (about half of them grazing: 60-89.9
// degrees off the height axis, and some along a face) and from cameras inside the box.
std::vector<Ray> randomRays(const PackReader& pack, int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u01(0, 1);
  auto cells = pack.cells();
  std::vector<Ray> rays;
  while (int(rays.size()) < n) {
    const uint32_t ci = uint32_t(rng() % cells.size());
    const CellRecord& c = cells[ci];
    const Eigen::Vector3d lo(c.box[0], c.box[2], c.box[4]), hi(c.box[1], c.box[3], c.box[5]);
    const Eigen::Vector3d size = hi - lo;
    Eigen::Vector3d target = lo + Eigen::Vector3d(u01(rng), u01(rng), u01(rng)).cwiseProduct(size);
    const int kind = int(rng() % 4);
    double theta;  // off the height axis (w), pointing down (mostly)
    if (kind == 0) theta = std::acos(u01(rng));
    else if (kind == 1) theta = (60 + 29.9 * u01(rng)) * M_PI / 180;
    else theta = M_PI * u01(rng);  // any direction, upward ones too
    const double phi = 2 * M_PI * u01(rng);
    Eigen::Vector3d d(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), -std::cos(theta));
    if (kind == 2 && rng() % 3 == 0) {  // along a face: the ray lies in the plane u = uMin or v = vMax
      if (rng() % 2) { target.x() = lo.x(); d.x() = 0; } else { target.y() = hi.y(); d.y() = 0; }
      if (d.norm() < 1e-6) continue;
      d.normalize();
    }
    Ray r{ci, target, d, 0, 0};
    if (kind == 3) {  // camera inside the box
      r.o = lo + Eigen::Vector3d(u01(rng), u01(rng), u01(rng)).cwiseProduct(size);
    } else {
      r.o = target - d * (size.norm() * 2 + 1e-9);
    }
    double t0 = 0, t1 = 1e300;
    for (int a = 0; a < 3; ++a) {
      if (r.d[a] == 0) {
        if (r.o[a] < lo[a] || r.o[a] > hi[a]) t0 = 1, t1 = 0;
        continue;
      }
      double ta = (lo[a] - r.o[a]) / r.d[a], tb = (hi[a] - r.o[a]) / r.d[a];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    if (!(t0 < t1)) continue;
    r.t0 = t0;
    r.t1 = t1;
    rays.push_back(r);
  }
  return rays;
}

// The first above->below crossing inside the covered region by a march at 1/32 texel over
// CpuRaycaster::height (the shader's sampleHeight in double), then bisection: an answer that shares
// no code with the traversal. It can miss crossings thinner than its step, so the test only
// counts disagreements.
bool fineMarch(const CpuRaycaster& rc, const CellRecord& c, const Ray& r, double& tHit) {
  const double texel = std::min((c.box[1] - c.box[0]) / c.tileW, (c.box[3] - c.box[2]) / c.tileH);
  const double horiz = std::max(1e-300, std::hypot(r.d.x(), r.d.y()));
  const double dt = std::min((r.t1 - r.t0) / 64, texel / 32 / horiz);
  auto gap = [&](double t, bool& cov) {
    const Eigen::Vector3d p = r.o + r.d * t;
    const double h = rc.height(c, p.x(), p.y());
    cov = !std::isnan(h);
    return cov ? p.z() - h : 0.0;
  };
  bool covPrev;
  double gPrev = gap(r.t0, covPrev), tPrev = r.t0;
  for (double t = r.t0 + dt;; t += dt) {
    const bool last = t >= r.t1;
    if (last) t = r.t1;
    bool cov;
    const double g = gap(t, cov);
    if (cov && g <= 0 && covPrev && gPrev > 0) {
      double lo = tPrev, hi = t;
      for (int k = 0; k < 80; ++k) {
        const double m = 0.5 * (lo + hi);
        bool cm;
        const double gm = gap(m, cm);
        (!cm || gm > 0 ? lo : hi) = m;
      }
      tHit = hi;
      return true;
    }
    if (last) return false;
    tPrev = t;
    gPrev = g;
    covPrev = cov;
  }
}

struct PackCase {
  const char* name;
  const char* source;
};

class ExactTrace : public ::testing::TestWithParam<PackCase> {};

TEST_P(ExactTrace, PyramidEqualsEveryPatchAndAFineMarch) {
  ASSERT_TRUE(test::haveSharedData()) << "../shared/data is missing";
  test::TempDir dir;
  auto input = InputSet::open({test::sharedData(GetParam().source)});
  ASSERT_TRUE(input.isOk()) << input.status().message();
  PackSummary sum;
  ASSERT_TRUE(packInput(*input, dir.file("p.hfa"), PackOptions{}, nullptr, sum).isOk());
  PackReader pack;
  ASSERT_TRUE(pack.open(dir.file("p.hfa")).isOk());
  const exact::Pyramids pyr = exact::buildPyramids(pack);
  const CpuRaycaster rc(pack);
  const std::vector<Ray> rays = randomRays(pack, 20000, 7);
  size_t exactLate = 0, hits = 0, linearDiffers = 0, capped = 0, marchCompared = 0, marchDiffers = 0;
  std::vector<uint32_t> visits;
  double maxDiff = 0;
  for (const Ray& r : rays) {
    const CellRecord& c = pack.cells()[r.cell];
    const double texel = std::min((c.box[1] - c.box[0]) / c.tileW, (c.box[3] - c.box[2]) / c.tileH);
    exact::TraceStats st;
    double tp = 0, tl = 0;
    const bool hp = exact::traceCell(pack, c, pyr.codes.data() + pyr.offsets[r.cell], r.o, r.d, r.t0, r.t1, tp, &st);
    const bool hl = exact::traceCellLinear(pack, c, r.o, r.d, r.t0, r.t1, tl);
    visits.push_back(st.nodeVisits);
    capped += st.capped;
    hits += hp;
    if (hp != hl || (hp && std::abs(tp - tl) > 1e-9 * texel)) ++linearDiffers;
    // Against the march: where both answer, or where one does; a hit must lie on the surface.
    double tm = 0;
    const bool hm = fineMarch(rc, c, r, tm);
    ++marchCompared;
    const bool differs = hp != hm || (hp && std::abs(tp - tm) > 0.01 * texel);
    marchDiffers += differs;
    if (differs) {
      // The exact root may only be earlier than the march's (a crossing thinner than its step) or
      // alone; a later or missing exact hit is a crossing the traversal skipped.
      if (hm && (!hp || tp > tm)) {
        ++exactLate;
        const Eigen::Vector3d pm = r.o + r.d * tm;
        std::printf("  late: cell %u hp %d tp %.9g tm %.9g (texel %.3g) at (%.6g %.6g %.6g) h %.9g d (%.4g %.4g %.4g) W %d H %d box w %.6g..%.6g\n",
                    r.cell, int(hp), tp, tm, texel, pm.x(), pm.y(), pm.z(), rc.height(c, pm.x(), pm.y()), r.d.x(), r.d.y(), r.d.z(),
                    c.tileW, c.tileH, c.box[4], c.box[5]);
      }
    }
    if (hp && hm) maxDiff = std::max(maxDiff, std::abs(tp - tm) / texel);
  }
  std::sort(visits.begin(), visits.end());
  auto pct = [&](double q) { return visits[std::min(visits.size() - 1, size_t(q * double(visits.size())))]; };
  std::printf("[exact] %s: %zu rays, %zu hits; pyramid vs every patch: %zu differ; vs 1/32-texel march: %zu of %zu "
              "differ (%.3f%%; the march earlier or alone: %zu), max |dt| %.3g texel; node visits p50 %u p90 %u p99 %u max %u; capped %zu\n",
              GetParam().name, rays.size(), hits, linearDiffers, marchDiffers, marchCompared,
              100.0 * double(marchDiffers) / double(marchCompared), exactLate, maxDiff, pct(0.5), pct(0.9), pct(0.99),
              visits.back(), capped);
  EXPECT_GT(hits, rays.size() / 10);
  EXPECT_EQ(linearDiffers, 0u);
  EXPECT_EQ(capped, 0u);
  EXPECT_EQ(exactLate, 0u);
  // This mix is harder than a view (a quarter of the rays graze at 60-89.9 degrees from random
  // heights, a quarter start inside the box), and grazing rays cross more nodes in larger tiles:
  // measured p99 62 (dragon), 66 (bunny scans in 1642 cells) and 93 (the same scans in 1045
  // larger cells once their normals' signs were propagated). The GPU counters over the stress
  // suite's views are held to the 64 (stress_test).
  EXPECT_LE(pct(0.99), 100u);
  // The march steps over crossings thinner than 1/32 texel (grazing rays over a crest, quadrant
  // pieces at coverage edges); the exact root does not. Measured: see the printed line.
  EXPECT_LE(double(marchDiffers), 0.002 * double(marchCompared));
}

INSTANTIATE_TEST_SUITE_P(RealPacks, ExactTrace,
                         ::testing::Values(PackCase{"BunnyScans", "stanford_bunny/scans/bun.conf"},
                                           PackCase{"DragonMesh", "stanford_dragon/reconstruction/dragon_vrip.ply"}),
                         [](const auto& info) { return std::string(info.param.name); });

// The pyramid's nodes bound their patches: every covered piece's corner heights lie at or below
// its level-0 code, and each level is the 2x2 maximum of the one below.
TEST(ExactPyramid, LevelsAreMaximaAndSizesRoundUp) {
  const exact::Levels lv = exact::levelsOf(5, 2);  // 6 x 3 patches
  ASSERT_EQ(lv.count, 4);
  EXPECT_EQ(lv.w[0], 6);
  EXPECT_EQ(lv.h[0], 3);
  EXPECT_EQ(lv.w[1], 3);
  EXPECT_EQ(lv.h[1], 2);
  EXPECT_EQ(lv.w[2], 2);
  EXPECT_EQ(lv.h[2], 1);
  EXPECT_EQ(lv.w[3], 1);
  EXPECT_EQ(lv.h[3], 1);
  EXPECT_EQ(lv.total, 18u + 6u + 2u + 1u);
  const exact::Levels one = exact::levelsOf(1, 1);  // 2 x 2 patches, then 1
  EXPECT_EQ(one.count, 2);
  EXPECT_EQ(one.total, 5u);
}

}  // namespace
}  // namespace sa
