// The exact mode's CPU traversal (modes/exact/exact.h), GL-free: the maximum-mipmap traversal
// against every patch along the ray (the same root solver without the pyramid), and both
// against an independent fine march over CpuRaycaster::height (the sampling rule of the shader),
// on real packs: the bunny's raw scans (holes, scan edges, stored normals) and the dragon mesh.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>

#include "common/ray_box.h"
#include "atlas/raycast.h"
#include "modes/exact/exact.h"
#include "preprocess/pipeline.h"
#include "../common/pack_util.h"

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
    if (!clipRayToBox(lo, hi, r.o, r.d, t0, t1)) continue;
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
  test::TempDir dir;
  PackReader pack;
  const Status packed = test::packShared(dir, GetParam().source, pack);
  ASSERT_TRUE(packed.isOk()) << packed.message();
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
  // heights, a quarter start inside the box), and grazing rays cross more nodes in larger tiles.
  // With maxima only the p99 was 93 (bunny scans, 1045 cells) and 62 (dragon): rays under the
  // sheet solved every patch they crossed; with the minima 30 and 26.
  EXPECT_LE(pct(0.99), 64u);
  // The march steps over crossings thinner than 1/32 texel (grazing rays over a crest, quadrant
  // pieces at coverage edges); the exact root does not. Measured: see the printed line.
  EXPECT_LE(double(marchDiffers), 0.002 * double(marchCompared));
}

INSTANTIATE_TEST_SUITE_P(RealPacks, ExactTrace,
                         ::testing::Values(PackCase{"BunnyScans", "stanford_bunny/scans/bun.conf"},
                                           PackCase{"DragonMesh", "stanford_dragon/reconstruction/dragon_vrip.ply"}),
                         [](const auto& info) { return std::string(info.param.name); });

// On a real pack, every node bounds the rendered surface under it from above and below: the
// surface sampled at random points of every patch lies within its level-0 codes, and each level's
// codes are the maximum and minimum of the four below.
TEST(ExactPyramid, NodesBoundTheSurfaceFromAboveAndBelow) {
  test::TempDir dir;
  PackReader pack;
  const Status packed = test::packShared(dir, "stanford_bunny/scans/bun.conf", pack);
  ASSERT_TRUE(packed.isOk()) << packed.message();
  const exact::Pyramids pyr = exact::buildPyramids(pack);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> unit(0, 1);
  size_t samples = 0, outside = 0, floored = 0, parentsWrong = 0;
  for (size_t ci = 0; ci < pack.cells().size(); ++ci) {
    const CellRecord& c = pack.cells()[ci];
    const uint16_t* codes = pyr.codes.data() + pyr.offsets[ci];
    const exact::Levels lv = exact::levelsOf(c.tileW, c.tileH);
    const double tu = (c.box[1] - c.box[0]) / c.tileW, tv = (c.box[3] - c.box[2]) / c.tileH;
    for (int py = 0; py < lv.h[0]; ++py)
      for (int px = 0; px < lv.w[0]; ++px) {
        const uint16_t* node = codes + 2 * (uint64_t(py) * lv.w[0] + px);
        floored += node[0] != exact::kNodeEmpty && node[1] != 0;
        for (int k = 0; k < 4; ++k) {
          // Patch (px, py) spans texel coordinates [px - 1/2, px + 1/2) (the gutter ring clamps).
          const double u = c.box[0] + (px - 0.5 + unit(rng)) * tu, v = c.box[2] + (py - 0.5 + unit(rng)) * tv;
          if (u < c.box[0] || u > c.box[1] || v < c.box[2] || v > c.box[3]) continue;
          const double h = exact::surfaceHeight(pack, c, u, v);
          if (std::isnan(h)) continue;
          ++samples;
          const double hi = node[0] == exact::kNodeUnbounded ? 1e300 : decodeHeight(node[0], c.box[4], c.box[5]);
          const double lo = node[1] == 0 ? -1e300 : decodeHeight(node[1], c.box[4], c.box[5]);
          outside += node[0] == exact::kNodeEmpty || h > hi || h < lo;
        }
      }
    for (int l = 1; l < lv.count; ++l)
      for (int y = 0; y < lv.h[l]; ++y)
        for (int x = 0; x < lv.w[l]; ++x) {
          uint16_t top = exact::kNodeEmpty, bottom = exact::kNodeNoFloor;
          for (int k = 0; k < 4; ++k) {
            const int bx = 2 * x + (k & 1), by = 2 * y + (k >> 1);
            if (bx >= lv.w[l - 1] || by >= lv.h[l - 1]) continue;
            const uint16_t* child = codes + 2 * (lv.offset[l - 1] + uint64_t(by) * lv.w[l - 1] + bx);
            top = std::max(top, child[0]);
            bottom = std::min(bottom, child[1]);
          }
          const uint16_t* node = codes + 2 * (lv.offset[l] + uint64_t(y) * lv.w[l] + x);
          parentsWrong += node[0] != top || node[1] != bottom;
        }
  }
  std::printf("[exact] bunny scans: %zu surface samples, %zu outside their node's bounds; %zu nodes with a floor; "
              "%zu parents wrong\n", samples, outside, floored, parentsWrong);
  EXPECT_GT(samples, 100000u);
  EXPECT_EQ(outside, 0u);
  EXPECT_GT(floored, samples / 8);  // the minima are real bounds, not all "unbounded below"
  EXPECT_EQ(parentsWrong, 0u);

  // A pack baked before the minima (section version 1) is refused with what to do, not misread.
  ExtraSection old = exact::bakeSection(pack);
  const uint32_t v1 = 1;
  std::memcpy(old.bytes.data(), &v1, 4);
  ASSERT_TRUE(rewritePackWithSections(pack, dir.file("old.hfa"), {old}).isOk());
  PackReader oldPack;
  ASSERT_TRUE(oldPack.open(dir.file("old.hfa")).isOk());
  auto v = exact::readSection(oldPack);
  ASSERT_FALSE(v.isOk());
  EXPECT_NE(v.status().message().find("version 1"), std::string::npos) << v.status().message();
  EXPECT_NE(v.status().message().find("scanatlas bake PACK --mode exact"), std::string::npos) << v.status().message();
  auto fresh = exact::readSection(pack);
  EXPECT_TRUE(fresh.isOk() && !fresh->present);  // the packed file itself has no XMAX
}

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
