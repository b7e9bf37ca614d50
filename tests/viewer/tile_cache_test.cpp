// The --gpu-budget cache's parts without GL: the buddy allocator, the coarser tile levels and the
// residency plan (levels from the texels' size on screen, the budget, eviction).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "../common/render_util.h"
#include "viewer/tile_cache.h"

namespace sa {
namespace {

// A 20000-point sphere's pack (8 cells) in d.
std::string packSphere(const test::TempDir& d) {
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(20000, 1.0, Eigen::Vector3d::Zero(), pts, nrm);
  return test::packPoints(d, pts, nrm, "s");
}

bool overlap(const BlockAllocator::Block& a, const BlockAllocator::Block& b) {
  return a.layer == b.layer && a.x < b.x + b.w && b.x < a.x + a.w && a.y < b.y + b.h && b.y < a.y + a.h;
}

TEST(BlockAllocator, BlocksNeverOverlapAndFreedSpaceMergesBack) {
  BlockAllocator al(256, 2);
  EXPECT_EQ(al.capacityTexels(), 2u * 256 * 256);
  std::mt19937 rng(7);
  std::vector<BlockAllocator::Block> live;
  for (int round = 0; round < 2000; ++round) {
    if (!live.empty() && (rng() % 3 == 0 || live.size() > 60)) {
      const size_t k = rng() % live.size();
      al.release(live[k]);
      live.erase(live.begin() + ptrdiff_t(k));
      continue;
    }
    const uint32_t w = 1 + rng() % 70, h = 1 + rng() % 70;
    BlockAllocator::Block b;
    if (!al.allocate(w, h, b)) continue;
    EXPECT_GE(b.w, w);
    EXPECT_GE(b.h, h);
    EXPECT_LT(b.w, 2 * std::max(w, 1u) + 1);
    EXPECT_LE(b.x + b.w, 256u);
    EXPECT_LE(b.y + b.h, 256u);
    for (const auto& o : live) ASSERT_FALSE(overlap(b, o));
    live.push_back(b);
  }
  uint64_t used = 0;
  for (const auto& b : live) used += uint64_t(b.w) * b.h;
  EXPECT_EQ(al.usedTexels(), used);
  for (const auto& b : live) al.release(b);
  EXPECT_EQ(al.usedTexels(), 0u);
  // Everything merged back: a whole layer fits again, twice, and a third does not.
  BlockAllocator::Block a, b, c;
  EXPECT_TRUE(al.allocate(256, 256, a));
  EXPECT_TRUE(al.allocate(200, 256, b));
  EXPECT_FALSE(al.allocate(1, 1, c));
}

TEST(TileMips, CoarserLevelsAverageTheCoveredTexels) {
  test::TempDir d;
  PackReader p;
  ASSERT_TRUE(p.open(packSphere(d)).isOk());
  for (uint32_t i = 0; i < p.cells().size(); ++i) {
    const CellRecord& c = p.cells()[i];
    std::vector<TileImage> all, m;
    ASSERT_TRUE(buildLevels(p, i, 0, all).isOk());
    ASSERT_GE(all.size(), 2u);
    // Level 0 is the pack's tile with its gutter.
    ASSERT_EQ(all[0].heights.size(), size_t(c.tileW + 2) * (c.tileH + 2));
    for (int j = -1; j <= int(c.tileH); ++j)
      for (int k = -1; k <= int(c.tileW); ++k)
        ASSERT_EQ(all[0].heights[size_t(j + 1) * (c.tileW + 2) + size_t(k + 1)], p.texel(c, k, j));
    // Kept from level 2: the finer ones sized but empty, the rest the same texels.
    ASSERT_TRUE(buildLevels(p, i, 2, m).isOk());
    ASSERT_EQ(m.size(), all.size());
    for (uint32_t k = 0; k < m.size(); ++k) {
      EXPECT_EQ(m[k].w, all[k].w);
      EXPECT_EQ(m[k].heights.empty(), k < 2 && all.size() > k);
      if (k >= 2) {
        EXPECT_EQ(m[k].heights, all[k].heights);
      }
    }
    EXPECT_LT(levelBytes(m), levelBytes(all));
    m.assign(all.begin() + 1, all.end());
    // Level 1 texel (0, 0): its footprint is [0, 2 w / (w + 1)) in level 0's texels (2 where w is
    // even): the covered texels' area-weighted mean, covered where its mask is. A sixteenth
    // inside one level-0 texel is covered where that texel is.
    const double fu = 2.0 * c.tileW / m[0].w, fv = 2.0 * c.tileH / m[0].h;
    double sum = 0, covered = 0;
    for (int j = 0; j < std::min<int>(2, c.tileH); ++j)
      for (int k = 0; k < std::min<int>(2, c.tileW); ++k) {
        const double wt = std::clamp(fu / 2 - k, 0.0, 1.0) * std::clamp(fv / 2 - j, 0.0, 1.0);
        if (uint16_t v = p.texel(c, k, j)) sum += wt * v, covered += wt;
      }
    const size_t o = size_t(1) * (m[0].w + 2) + 1;
    const uint16_t got = m[0].heights[o], mask = m[0].cover[o];
    EXPECT_EQ(got != 0, mask != 0);
    if (got) {
      EXPECT_NEAR(got, sum / covered, 0.51);
    }
    for (int b = 0; b < 4; ++b)
      for (int a = 0; a < 4; ++a) {
        const int x0 = int(a * fu / 4), x1 = int(std::ceil((a + 1) * fu / 4)) - 1;
        const int y0 = int(b * fv / 4), y1 = int(std::ceil((b + 1) * fv / 4)) - 1;
        if (x0 != x1 || y0 != y1 || x0 >= c.tileW || y0 >= c.tileH) continue;
        EXPECT_EQ((mask >> (4 * b + a)) & 1, p.texel(c, x0, y0) != 0) << "sixteenth " << a << ", " << b;
      }
    // The gutter repeats the edge.
    EXPECT_EQ(m[0].heights[0], m[0].heights[o]);
    EXPECT_EQ(m[0].cover[0], mask);
  }
}

// Checks each mask of level t (built from `finer`) as FORMAT.md words it: a sixteenth covered
// where 2 of its quarters' centres are (coveredAt on the finer level). Counts the set and clear
// bits into *set and *clear where given.
::testing::AssertionResult masksFollowTheRule(const TileImage& finer, const TileImage& t, int* set = nullptr,
                                              int* clear = nullptr) {
  for (uint32_t j = 0; j < t.h; ++j)
    for (uint32_t i = 0; i < t.w; ++i)
      for (int b = 0; b < 4; ++b)
        for (int a = 0; a < 4; ++a) {
          int votes = 0;
          for (int q = 0; q < 4; ++q)
            votes += coveredAt(finer, (i + (a + ((q & 1) + 0.5) / 2) / 4) / t.w, (j + (b + ((q >> 1) + 0.5) / 2) / 4) / t.h);
          const int bit = (t.cover[size_t(j + 1) * (t.w + 2) + i + 1] >> (4 * b + a)) & 1;
          if (bit != (votes >= 2 ? 1 : 0))
            return ::testing::AssertionFailure() << "level " << t.w << " x " << t.h << ", texel " << i << ", " << j
                                                 << ", sixteenth " << a << ", " << b << ": bit " << bit << ", " << votes
                                                 << " votes";
          if (bit && set) ++*set;
          if (!bit && clear) ++*clear;
        }
  return ::testing::AssertionSuccess();
}

// A coarse level's coverage (its masks) keeps level 0's edges to a sixteenth of its texel, however
// far the level is from level 0, and drops what is under a quarter of a texel: a one-texel hole
// and a one-texel speck are gone by level 3 (a far view would show them in pixels that a pixel's
// ray picks by chance). Without masks an edge moved by up to half a coarse texel.
TEST(TileMips, CoarseMasksKeepLevelZerosCoverageEdges) {
  for (uint32_t W : {96u, 75u}) {
    TileImage t = blankTile(W, W, false, false);
    const double edge = 37.3;  // covered where u < edge (level 0's texel units)
    auto inside = [&](int i, int j) { return i + 0.5 < edge + 0.25 * j; };
    for (int j = 0; j < int(W); ++j)
      for (int i = 0; i < int(W); ++i) t.heights[size_t(j + 1) * (W + 2) + i + 1] = inside(i, j) ? 1000 : 0;
    t.heights[size_t(60 + 1) * (W + 2) + 10 + 1] = 0;     // a hole
    t.heights[size_t(20 + 1) * (W + 2) + 70 + 1] = 1000;  // a speck
    const TileImage level0 = t;
    for (int level = 1; level <= 5; ++level) {
      const TileImage finer = t;
      t = coarserLevel(t);
      ASSERT_TRUE(masksFollowTheRule(finer, t)) << "width " << W << ", level " << level;
      const double sixteenth = double(W) / t.w / 4;  // in level 0's texels
      int wrong = 0, far = 0;
      for (int j = 0; j < int(W); ++j)
        for (int i = 0; i < int(W); ++i) {
          const double x = (i + 0.5) / W, y = (j + 0.5) / W;
          const bool want = coveredAt(level0, x, y), got = coveredAt(t, x, y);
          const double fromEdge = std::abs(i + 0.5 - (edge + 0.25 * j));
          const double fromDots = std::min(std::hypot(i - 10, j - 60), std::hypot(i - 70, j - 20));
          if (want == got) continue;
          ++wrong;
          if (std::min(fromEdge, fromDots) > 1.5 * sixteenth + 1) ++far;
        }
      EXPECT_EQ(far, 0) << "width " << W << ", level " << level << ": " << wrong << " texels differ";
      if (level >= 3) {
        EXPECT_TRUE(coveredAt(t, 10.5 / W, 60.5 / W)) << "the hole is closed at level " << level;
        EXPECT_FALSE(coveredAt(t, 70.5 / W, 20.5 / W)) << "the speck is gone at level " << level;
      }
      if (level <= 2 && W % 4 == 0) {
        EXPECT_EQ(wrong, 0) << "a sixteenth of level " << level << " is at most a texel of level 0";
        EXPECT_FALSE(coveredAt(t, 10.5 / W, 60.5 / W)) << "the hole is kept at level " << level;
      }
    }
  }
}

// The masks follow FORMAT.md's rule (a sixteenth covered where 2 of its quarters' centres are)
// on random coverage too, on tiles of even and odd sides, wide and tall, down to one texel.
TEST(TileMips, MasksFollowTheRuleOnRandomCoverage) {
  std::mt19937 rng(7);
  for (auto [W, H] : {std::pair{40u, 23u}, std::pair{17u, 64u}, std::pair{9u, 9u}, std::pair{2u, 3u}}) {
    for (double density : {0.2, 0.5, 0.9}) {
      TileImage t = blankTile(W, H, false, false);
      std::bernoulli_distribution cov(density);
      for (uint32_t j = 0; j < H; ++j)
        for (uint32_t i = 0; i < W; ++i) t.heights[size_t(j + 1) * (W + 2) + i + 1] = cov(rng) ? 500 : 0;
      int set = 0, clear = 0;
      while (t.w > 1 || t.h > 1) {
        const TileImage finer = t;
        t = coarserLevel(t);
        ASSERT_TRUE(masksFollowTheRule(finer, t, &set, &clear)) << W << " x " << H << ", density " << density;
      }
      if (W * H < 64) continue;  // a few texels may come out all covered or all open
      EXPECT_GT(set, 0) << W << " x " << H << ", density " << density;
      EXPECT_GT(clear, 0) << W << " x " << H << ", density " << density;
    }
  }
}

// The shader spreads each level's texels evenly over the cell's box; on a linear ramp across a
// tile of odd width every level's texel must hold the ramp where it is drawn, within a tenth of
// that level's texel (measured at most 0.08). A 2 x 2 mean drifts toward the far edge by 0.47
// of a texel at level 1 and 0.74 at level 3 (7.75 fine texels at level 5, 33 wide).
TEST(TileMips, EachLevelStaysWhereTheShaderDrawsIt) {
  for (uint32_t W : {33u, 37u, 64u, 5u}) {
    TileImage t;
    t.w = W;
    t.h = 3;
    t.heights.assign(size_t(W + 2) * 5, 0);
    for (uint32_t j = 0; j < 5; ++j)
      for (uint32_t i = 0; i < W + 2; ++i) t.heights[size_t(j) * (W + 2) + i] = uint16_t(1000 + 100 * std::clamp<int>(int(i) - 1, 0, int(W) - 1));
    double worst = 0;
    for (int level = 1; t.w > 1; ++level) {
      t = coarserLevel(t);
      for (uint32_t i = 0; i < t.w; ++i) {
        const double x = (i + 0.5) / t.w * W - 0.5;  // where the shader draws texel i, in level 0's texels
        const double got = (t.heights[size_t(1) * (t.w + 2) + i + 1] - 1000) / 100.0;
        ASSERT_GT(t.heights[size_t(1) * (t.w + 2) + i + 1], 0) << "covered";
        worst = std::max(worst, std::abs(got - x) * t.w / W);
      }
      EXPECT_LE(worst, 0.1) << "width " << W << ", level " << level;
    }
  }
}

// Without --gpu-budget: no budget while the pages fit a quarter of RAM and half the GPU's
// memory (where it is known), else the smaller room, never under 16 MiB.
TEST(GpuBudgetDefault, OnlyWhereThePagesOutgrowTheMemory) {
  const uint64_t M = uint64_t(1) << 20, G = uint64_t(1) << 30;
  EXPECT_EQ(defaultGpuBudget(100 * M, 24 * G, 0), 0u);
  EXPECT_EQ(defaultGpuBudget(6 * G, 24 * G, 0), 0u) << "exactly a quarter still fits";
  EXPECT_EQ(defaultGpuBudget(7 * G, 24 * G, 0), 6 * G);
  EXPECT_EQ(defaultGpuBudget(3 * G, 24 * G, 4 * G), 2 * G) << "half the GPU's memory";
  EXPECT_EQ(defaultGpuBudget(3 * G, 24 * G, 8 * G), 0u);
  EXPECT_EQ(defaultGpuBudget(100 * M, 64 * M, 0), 16 * M) << "at least 16 MiB";
  EXPECT_EQ(defaultGpuBudget(100 * G, 0, 0), 0u) << "nothing known: everything resident, as before";
  EXPECT_GT(physicalMemoryBytes(), 64 * M);
  test::TempDir d;
  PackReader p;
  ASSERT_TRUE(p.open(packSphere(d), PageLoad::kNone).isOk());
  EXPECT_EQ(atlasBytes(p), p.pageTexels() * p.meta().pageCount * (2 + (p.hasNormals() ? kNormalBytes : 0) + (p.hasColor() ? 4 : 0)));
}

// The sphere's pack opened with every page, and all its cells as one visible set.
struct SphereCells {
  test::TempDir d;
  PackReader p;
  std::vector<uint32_t> all;
  bool open() {
    if (!p.open(packSphere(d)).isOk()) return false;
    all.resize(p.cells().size());
    for (uint32_t i = 0; i < all.size(); ++i) all[i] = i;
    return true;
  }
};

// The level a texel's size on screen asks for: the coarsest whose texels stay under
// kMaxTexelPx pixels (their diagonals under one), the next coarser's over it.
TEST(TileResidency, AViewAsksForTheCoarsestLevelWhoseTexelsStayUnderTheirLimit) {
  EXPECT_EQ(TileResidency::levelForTexelPx(3.0), 0u);
  EXPECT_EQ(TileResidency::levelForTexelPx(0.8), 0u) << "a texel over the limit but no finer level";
  EXPECT_EQ(TileResidency::levelForTexelPx(0.9), 0u);
  EXPECT_EQ(TileResidency::levelForTexelPx(0.5), 0u) << "0.5 px: level 1 would be 1 px, its diagonal 1.41";
  EXPECT_EQ(TileResidency::levelForTexelPx(0.3), 1u);
  for (double px = 1e-4; px < kMaxTexelPx; px *= 1.037) {
    const uint32_t lv = TileResidency::levelForTexelPx(px);
    EXPECT_LE(px * double(1u << lv), kMaxTexelPx * (1 + 1e-12)) << px;
    EXPECT_GT(px * double(2u << lv), kMaxTexelPx) << px;
    EXPECT_LE(std::sqrt(2.0) * px * double(1u << lv), 1.0 + 1e-12) << "the texel's diagonal under a pixel at " << px;
  }
}

TEST(TileResidency, LevelsFollowTheScreenAndTheBudgetEvictsWhatIsNotSeen) {
  SphereCells sc;
  ASSERT_TRUE(sc.open());
  const PackReader& p = sc.p;
  const uint32_t n = uint32_t(p.cells().size());
  const std::vector<uint32_t>& all = sc.all;
  std::vector<uint8_t> decoded(n, 0);  // every level in memory
  const Eigen::Vector3d eye(0, 0, 4);  // relative to the pack origin, which is near the centre
  // Near, with room for everything: every cell at level 0.
  TileResidency big(p.cells(), 512, 64, 10);
  auto f = big.plan(all, decoded.data(), eye - Eigen::Vector3d(p.meta().origin), 1e6, UINT64_MAX);
  EXPECT_EQ(f.bias, 0);
  EXPECT_EQ(f.uploads.size(), n);
  for (uint32_t i = 0; i < n; ++i) EXPECT_EQ(big.level(i), 0);
  // Far (a few pixels per cell): coarser levels, fewer bytes.
  const uint64_t nearBytes = big.residentBytes();
  f = big.plan(all, decoded.data(), eye - Eigen::Vector3d(p.meta().origin), 20, UINT64_MAX);
  for (uint32_t i = 0; i < n; ++i) EXPECT_GT(big.level(i), 0) << i;
  EXPECT_LT(big.residentBytes(), nearBytes);
  // A cache too small for level 0: all coarser, within its capacity; not decoded: waiting.
  TileResidency small(p.cells(), 256, 1, 10);
  decoded[0] = TileResidency::kNoLevel;
  f = small.plan(all, decoded.data(), eye - Eigen::Vector3d(p.meta().origin), 1e6, UINT64_MAX);
  EXPECT_GT(f.bias, 0);
  EXPECT_GT(f.coarsened, 0u);
  EXPECT_EQ(f.waiting, 1u);
  ASSERT_EQ(f.needs.size(), 1u);
  EXPECT_EQ(f.needs[0].cell, 0u);
  EXPECT_GT(f.needs[0].level, 0u) << "asked for at the level it will be drawn at";
  EXPECT_EQ(small.level(0), -1);
  EXPECT_LE(small.residentBytes(), small.capacityBytes());
  // Cells no longer seen make room for the ones now seen.
  decoded[0] = 0;
  uint32_t x = 0;  // the cell with the largest tile gets a layer of its own block's size
  for (uint32_t i = 0; i < n; ++i)
    if (p.cells()[i].tileW * p.cells()[i].tileH > p.cells()[x].tileW * p.cells()[x].tileH) x = i;
  auto pow2 = [](uint32_t v) {
    uint32_t q = 1;
    while (q < v) q <<= 1;
    return q;
  };
  const uint32_t bw = pow2(p.cells()[x].tileW + 2u), bh = pow2(p.cells()[x].tileH + 2u);
  // One cell a view, each cell twice: every block at most a quarter of the layer, all together more.
  TileResidency tiny(p.cells(), 2 * std::max(bw, bh), 1, 10);
  uint64_t blocks = 0;
  for (uint32_t i = 0; i < n; ++i) blocks += uint64_t(pow2(p.cells()[i].tileW + 2u)) * pow2(p.cells()[i].tileH + 2u) * 10;
  uint32_t evicted = 0;
  for (uint32_t k = 0; k < 2 * n; ++k) {
    const std::vector<uint32_t> one = {k % n};
    f = tiny.plan(one, decoded.data(), eye - Eigen::Vector3d(p.meta().origin), 1e6, UINT64_MAX);
    EXPECT_EQ(tiny.level(k % n), 0) << k;
    EXPECT_LE(tiny.residentBytes(), tiny.capacityBytes());
    evicted += f.evicted;
    EXPECT_EQ(f.dropped.size(), f.evicted);
  }
  std::printf("%u cells, level-0 blocks %.2fx the cache: %u evictions\n", n, double(blocks) / tiny.capacityBytes(), evicted);
  if (blocks > tiny.capacityBytes()) {
    EXPECT_GT(evicted, 0u);
  }
}

}  // namespace
// A view that does not fit: every cell `bias` levels coarser, then cells go back one level finer
// while the set fits, so more of the cache is used than the uniform bias leaves; and from any
// camera the plan settles (no cell waits for a block) within a few frames, where a block at the
// planned level cannot be found, at a coarser one.
TEST(TileResidency, AViewThatDoesNotFitIsFinerWhereItFitsAndAlwaysSettles) {
  SphereCells sc;
  ASSERT_TRUE(sc.open());
  const PackReader& p = sc.p;
  const uint32_t n = uint32_t(p.cells().size());
  const std::vector<uint32_t>& all = sc.all;
  std::vector<uint8_t> decoded(n, 0);
  const Eigen::Vector3d origin(p.meta().origin);
  auto pow2 = [](uint32_t v) {
    uint32_t q = 1;
    while (q < v) q <<= 1;
    return q;
  };
  auto block = [&](uint32_t c, uint32_t level) {
    uint32_t w, h;
    TileResidency::levelSize(p.cells()[c], level, w, h);
    return uint64_t(pow2(w + 2)) * pow2(h + 2);
  };
  TileResidency small(p.cells(), 256, 1, 1);  // bytes = texels
  auto f = small.plan(all, decoded.data(), Eigen::Vector3d(0, 0, 4) - origin, 1e6, UINT64_MAX);
  ASSERT_GT(f.bias, 0);
  uint64_t uniform = 0;
  uint32_t finer = 0;
  for (uint32_t c = 0; c < n; ++c) {
    ASSERT_GE(small.level(c), 0) << c;
    const uint32_t atBias = std::min<uint32_t>(uint32_t(f.bias), small.levels(c) - 1);
    uniform += block(c, atBias);
    EXPECT_LE(uint32_t(small.level(c)), atBias) << c;
    finer += uint32_t(small.level(c)) < atBias;
  }
  std::printf("bias %d: %u of %u cells a level finer, %.1f %% of the cache used (uniform bias: %.1f %%)\n", f.bias,
              finer, n, 100.0 * small.residentBytes() / small.capacityBytes(), 100.0 * uniform / small.capacityBytes());
  EXPECT_GT(finer, 0u);
  EXPECT_GT(small.residentBytes(), uniform);
  EXPECT_LE(small.residentBytes() * 10, small.capacityBytes() * 7);
  // Cameras all around, near and far, each held until its plan uploads nothing and nothing waits.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int view = 0; view < 40; ++view) {
    const Eigen::Vector3d eye = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized() * (1.5 + 3 * (u(rng) + 1));
    const double focal = 400 * (u(rng) + 1.5);
    for (int frames = 0;; ++frames) {
      f = small.plan(all, decoded.data(), eye - origin, focal, UINT64_MAX);
      if (f.uploads.empty() && f.waiting == 0) break;
      ASSERT_LT(frames, 8) << "view " << view << " does not settle: " << f.waiting << " waiting";
    }
    EXPECT_LE(small.residentBytes(), small.capacityBytes());
  }
}

}  // namespace sa
