// Chunk halos (preprocess/chunk_halo.h): each target chunk gets exactly the other chunks' points
// within the margin of its cube, in the order of their sources and, within one, of their records
// (cut at a limit where one is given); the fragments are consumed; the sources' lists survive the
// trip between MPI ranks as bytes.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <random>

#include "../common/test_util.h"
#include "preprocess/chunk_halo.h"

namespace sa {
namespace {

// Chunks: the 8 octants at level 1, except the (0, 0, 0) octant split into its 8 children at
// level 2, so that chunks of two sizes meet.
std::vector<ChunkInfo> mixedChunks() {
  std::vector<ChunkInfo> chunks;
  for (uint32_t z = 0; z < 2; ++z)
    for (uint32_t y = 0; y < 2; ++y)
      for (uint32_t x = 0; x < 2; ++x) {
        ChunkInfo c;
        c.level = 1, c.ix = x, c.iy = y, c.iz = z;
        if (x || y || z) chunks.push_back(c);
      }
  for (uint32_t z = 0; z < 2; ++z)
    for (uint32_t y = 0; y < 2; ++y)
      for (uint32_t x = 0; x < 2; ++x) {
        ChunkInfo c;
        c.level = 2, c.ix = x, c.iy = y, c.iz = z;
        chunks.push_back(c);
      }
  return chunks;
}

double cubeDistance(const ChunkInfo& c, const uint32_t q[3]) {
  const double size = std::ldexp(1.0, 32 - c.level);
  const double lo[3] = {c.ix * size, c.iy * size, c.iz * size};
  double d2 = 0;
  for (int a = 0; a < 3; ++a) {
    const double x = q[a] + 0.5, e = std::max({lo[a] - x, 0.0, x - (lo[a] + size)});
    d2 += e * e;
  }
  return std::sqrt(d2);
}

TEST(ChunkHalo, EachChunkGetsTheOtherChunksPointsNearItsCube) {
  test::TempDir dir;
  const std::vector<ChunkInfo> chunks = mixedChunks();
  const ChunkLocator where(chunks);
  Quantizer qz;
  qz.cubeSize = 4294967296.0;  // one world unit per quantized step: the margin reads directly
  const double margin = 0.02 * 4294967296.0;
  // Random points in the root cube, each given to the chunk that holds it; many near faces.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<std::vector<ChunkPoint>> pts(chunks.size());
  for (int i = 0; i < 40000; ++i) {
    ChunkPoint p{};
    for (int a = 0; a < 3; ++a) {
      double f = u(rng);
      if (a == i % 3) f = 0.5 + (u(rng) - 0.5) * 0.1;  // crowd the middle planes, where chunks meet
      p.q[a] = uint32_t(f * 4294967295.0);
    }
    p.vid = uint32_t(i);
    const int64_t c = where.find(p.q);
    ASSERT_GE(c, 0);
    pts[size_t(c)].push_back(p);
  }
  HaloSet h{dir.path(), "t", {}};
  for (uint32_t s = 0; s < chunks.size(); ++s) ASSERT_TRUE(writeHalo(h, qz, chunks, where, s, pts[s], margin).isOk());
  // Across MPI ranks: two ranks' lists (the sources below 7 and the rest) as bytes, merged.
  HaloSet rank0 = h, rank1 = h, merged = h;
  for (uint32_t t = 0; t < chunks.size(); ++t) {
    std::erase_if(rank0.from[t], [](const auto& f) { return f.first >= 7; });
    std::erase_if(rank1.from[t], [](const auto& f) { return f.first < 7; });
  }
  mergeHaloSources(merged, {haloSources(rank1), haloSources(rank0)});
  EXPECT_EQ(merged.from, h.from);
  size_t total = 0;
  for (uint32_t t = 0; t < chunks.size(); ++t) {
    std::vector<uint32_t> want;  // vids, in the order of sources, then of records
    for (uint32_t s = 0; s < chunks.size(); ++s)
      if (s != t)
        for (const ChunkPoint& p : pts[s])
          if (cubeDistance(chunks[t], p.q) <= margin) want.push_back(p.vid);
    // Every other target with a limit: the halo is cut there, in the same order.
    const size_t limit = t % 2 ? SIZE_MAX : want.size() / 2;
    if (limit < want.size()) want.resize(limit);
    ChunkRecords got;
    ASSERT_TRUE(takeHalo(h, t, got, limit).isOk());
    std::vector<uint32_t> vids;
    for (const ChunkPoint& p : got) vids.push_back(p.vid);
    EXPECT_EQ(vids, want) << "target " << t;
    total += vids.size();
    for (const auto& [s, count] : h.from[t]) EXPECT_FALSE(std::filesystem::exists(h.path(s, t)));
  }
  EXPECT_GT(total, 4000u);  // the test saw halos
}

TEST(ChunkHalo, OneChunkOrNoMarginWritesNothing) {
  test::TempDir dir;
  std::vector<ChunkInfo> one(1);
  Quantizer qz;
  std::vector<ChunkPoint> pts(10);
  HaloSet h{dir.path(), "t", {}};
  ASSERT_TRUE(writeHalo(h, qz, one, ChunkLocator(one), 0, pts, 1.0).isOk());
  EXPECT_TRUE(h.empty());
  const std::vector<ChunkInfo> chunks = mixedChunks();
  ASSERT_TRUE(writeHalo(h, qz, chunks, ChunkLocator(chunks), 0, pts, 0.0).isOk());
  EXPECT_TRUE(h.empty());
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
}

TEST(ChunkHalo, LocatorFindsTheChunkHoldingAPosition) {
  const std::vector<ChunkInfo> chunks = mixedChunks();
  const ChunkLocator where(chunks);
  const uint32_t a[3] = {0, 0, 0}, b[3] = {0x3fffffffu, 0x40000000u, 0}, c[3] = {0xffffffffu, 0xffffffffu, 0xffffffffu};
  ASSERT_GE(where.find(a), 0);
  EXPECT_EQ(chunks[size_t(where.find(a))].level, 2);
  const ChunkInfo& cb = chunks[size_t(where.find(b))];
  EXPECT_EQ(cb.level, 2);
  EXPECT_EQ(cb.ix, 0u);
  EXPECT_EQ(cb.iy, 1u);
  const ChunkInfo& cc = chunks[size_t(where.find(c))];
  EXPECT_EQ(cc.level, 1);
  EXPECT_EQ(cc.ix + cc.iy + cc.iz, 3u);
  const std::vector<ChunkInfo> some(chunks.begin(), chunks.begin() + 3);  // a hole where the rest were
  EXPECT_EQ(ChunkLocator(some).find(a), -1);
}

}  // namespace
}  // namespace sa
