// The vdm mode's bake and lookup on the CPU (modes/vdm/vdm.h), the shader's interpolation
// mirrored: 20 cells of the bunny's raw scans x 20000 random off-grid queries (x, y, theta, phi)
// each, against the exact traversal from the same top-face point, and against the depth-only toy
// in the same run (one height fetch, d = (w_top - h) / cos theta).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "modes/exact/exact.h"
#include "modes/vdm/vdm.h"
#include "preprocess/pipeline.h"
#include "../common/pack_util.h"

namespace sa {
namespace {

TEST(Vdm, OffGridLookupsAgainstTheExactTraversalAndTheDepthOnlyToy) {
  test::TempDir dir;
  PackReader pack;
  const Status packed = test::packShared(dir, "stanford_bunny/scans/bun.conf", pack, "b");
  ASSERT_TRUE(packed.isOk()) << packed.message();
  const exact::Pyramids pyr = exact::buildPyramids(pack);
  // 20 cells with tiles of 16-64 texels a side (most texels of a pack are in such or larger
  // tiles; the bake of a 600-texel tile takes minutes), chosen at random.
  std::vector<uint32_t> pool;
  for (uint32_t i = 0; i < pack.cells().size(); ++i) {
    const CellRecord& c = pack.cells()[i];
    if (c.tileW >= 16 && c.tileH >= 16 && c.tileW <= 64 && c.tileH <= 64 && !(c.flags & kCellForced)) pool.push_back(i);
  }
  ASSERT_GE(pool.size(), 20u);
  std::mt19937 rng(11);
  std::shuffle(pool.begin(), pool.end(), rng);
  pool.resize(20);
  std::uniform_real_distribution<double> u01(0, 1);
  size_t exactHits = 0, vdmGood = 0, toyGood = 0, predictGood = 0, wrongHitMiss = 0, queries = 0;
  vdm::LookupStats st;
  double bytes = 0, texels = 0, bakeS = 0;
  int rankSum = 0;
  for (uint32_t ci : pool) {
    const CellRecord& c = pack.cells()[ci];
    const uint16_t* py = pyr.codes.data() + pyr.offsets[ci];
    const vdm::CellFunction fn = vdm::bakeCell(pack, ci, py);
    bytes += double(fn.bytes());
    texels += double(c.tileW) * c.tileH;
    bakeS += fn.bakeSeconds;
    rankSum += fn.rank;
    for (int q = 0; q < 20000; ++q) {  // the count
      const double u = c.box[0] + u01(rng) * (c.box[1] - c.box[0]), v = c.box[2] + u01(rng) * (c.box[3] - c.box[2]);
      const double theta = u01(rng) * vdm::kMaxThetaDeg * M_PI / 180, phi = u01(rng) * 2 * M_PI;
      const Eigen::Vector3d d = vdm::direction(theta, phi), o(u, v, c.box[5]);
      double t1 = 1e300;
      for (int a = 0; a < 3; ++a)
        if (d[a] != 0) t1 = std::min(t1, std::max((c.box[2 * a] - o[a]) / d[a], (c.box[2 * a + 1] - o[a]) / d[a]));
      double te = 0, tv = 0, tp = 0;
      const bool he = exact::traceCell(pack, c, py, o, d, 0, t1, te);
      const bool hv = vdm::lookup(pack, fn, py, u, v, d, tv, &st);
      const bool hp = vdm::lookup(pack, fn, py, u, v, d, tp, nullptr, true);
      ++queries;
      wrongHitMiss += he != hv;
      if (!he) continue;
      ++exactHits;
      const double tol = 0.5 * fn.texel;
      vdmGood += hv && std::abs(tv - te) <= tol;
      predictGood += hp && std::abs(tp - te) <= tol;
      // The toy: the height under the entry point, reached along the view.
      const double h = exact::surfaceHeight(pack, c, u, v);
      if (!std::isnan(h)) {
        const double tt = (c.box[5] - h) / std::cos(theta);
        toyGood += std::abs(tt - te) <= tol;
      }
    }
  }
  const double fb = double(st.fallbacks) / double(st.lookups);
  std::printf("[vdm] 20 cells (%.0f texels), rank mean %.1f, %.1f B/texel, bake %.2f s; %zu queries, %zu exact hits: "
              "within 0.5 texel: vdm %.1f%% (prediction alone %.1f%%), toy %.1f%%; hit/miss wrong %.2f%%; fallbacks %.1f%%, "
              "fast misses %.1f%%\n",
              texels, rankSum / 20.0, bytes / texels, bakeS, queries, exactHits, 100.0 * double(vdmGood) / double(exactHits),
              100.0 * double(predictGood) / double(exactHits), 100.0 * double(toyGood) / double(exactHits),
              100.0 * double(wrongHitMiss) / double(queries), 100 * fb, 100.0 * double(st.missedFast) / double(st.lookups));
  EXPECT_GT(exactHits, queries / 4);
  EXPECT_GE(double(vdmGood), 0.60 * double(exactHits));
  EXPECT_GE(double(vdmGood), 1.3 * double(toyGood));
  EXPECT_LE(double(wrongHitMiss), 0.05 * double(queries));
  EXPECT_LE(fb, 0.35);
}

}  // namespace
}  // namespace sa

namespace sa {
namespace {

// The section keeps to its byte budget and gives back exactly what the bake made.
TEST(Vdm, SectionKeepsItsBudgetAndRoundTrips) {
  test::TempDir dir;
  PackReader pack;
  const Status packed = test::packShared(dir, "stanford_bunny/scans/bun.conf", pack, "b");
  ASSERT_TRUE(packed.isOk()) << packed.message();
  for (uint64_t budget : {uint64_t(256) << 10, uint64_t(2) << 20}) {
    vdm::Selection sel;
    sel.budget = budget;
    vdm::BakeReport rep;
    const ExtraSection s = vdm::bakeSection(pack, sel, vdm::BakeOptions{}, rep);
    std::printf("[vdm] budget %llu: %u of %u cells baked, %llu bytes, %.1f s\n", (unsigned long long)budget, rep.baked,
                rep.candidates, (unsigned long long)s.bytes.size(), rep.seconds);
    EXPECT_LE(s.bytes.size(), budget);
    EXPECT_GT(rep.baked, 0u);
    if (budget > (1u << 20)) {
      ASSERT_TRUE(rewritePackWithSections(pack, dir.file("v.hfa"), {s}).isOk());
      PackReader v;
      ASSERT_TRUE(v.open(dir.file("v.hfa")).isOk());
      ASSERT_TRUE(v.verifyPages().isOk());
      auto view = vdm::readSection(v);
      ASSERT_TRUE(view.isOk()) << view.status().message();
      ASSERT_TRUE(view->present);
      uint32_t checked = 0;
      for (uint32_t i = 0; i < v.cells().size() && checked < 3; ++i) {
        if (view->entries[i] == vdm::kNoEntry) continue;
        std::vector<uint16_t> pyr;
        exact::buildCellPyramid(v, v.cells()[i], pyr);
        const vdm::CellFunction a = vdm::bakeCell(v, i, pyr.data()), b = vdm::cellFromSection(*view, i);
        ASSERT_EQ(a.rank, b.rank);
        EXPECT_EQ(a.hitBits, b.hitBits);
        EXPECT_EQ(a.mean, b.mean);
        EXPECT_EQ(a.basis, b.basis);
        EXPECT_EQ(a.weights, b.weights);
        ++checked;
      }
      EXPECT_EQ(checked, 3u);
    }
  }
}

}  // namespace
}  // namespace sa
