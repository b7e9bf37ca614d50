// The page coder's two forms (atlas/tile_codec.h): LOCO-I planes and the pyramid, lossless
// whatever the texels, and the snapping that makes the pyramid small without moving a texel
// past its tolerance.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "atlas/pack_format.h"
#include "atlas/tile_codec.h"
#include "atlas/tile_levels.h"

namespace sa {
namespace {

uint32_t valueAt(const uint8_t* p, int bytes) { return bytes == 2 ? uint32_t(p[0]) | uint32_t(p[1]) << 8 : p[0]; }
void setValue(uint8_t* p, int bytes, uint32_t v) {
  p[0] = uint8_t(v);
  if (bytes == 2) p[1] = uint8_t(v >> 8);
}

// A w x h tile: a smooth ramp plus noise of `noise` quanta, holes where `holes` says; values
// multiples of the layout's quantum, 0 in holes.
std::vector<uint8_t> makeTile(uint32_t w, uint32_t h, TexelLayout L, double noise, double holes, std::mt19937& rng,
                              std::vector<uint8_t>& cov) {
  const size_t tb = size_t(L.texelBytes());
  const uint32_t top = (L.bytes == 2 ? 0xffffu : 0xffu) / L.quantum;
  std::vector<uint8_t> t(size_t(w) * h * tb, 0);
  cov.assign(size_t(w) * h, 0);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> g(0, noise);
  const double a = u(rng), b = u(rng);
  for (uint32_t j = 0; j < h; ++j)
    for (uint32_t i = 0; i < w; ++i) {
      const size_t k = size_t(j) * w + i;
      if (u(rng) < holes) continue;
      cov[k] = 1;
      for (int c = 0; c < L.comps; ++c) {
        const double v = top * (0.3 + 0.2 * std::sin(a * i * 0.2 + c) + 0.2 * std::cos(b * j * 0.15)) + g(rng);
        setValue(&t[k * tb + size_t(c) * L.bytes], L.bytes, uint32_t(std::clamp(v, 1.0, double(top))) * L.quantum);
      }
    }
  return t;
}

// The tile placed in a page at (x, y) with its one-texel gutter repeating the edge.
std::vector<uint8_t> withGutter(const std::vector<uint8_t>& t, uint32_t w, uint32_t h, size_t tb, uint32_t pageWidth,
                                uint32_t x, uint32_t y, uint32_t pageHeight) {
  std::vector<uint8_t> page(size_t(pageWidth) * pageHeight * tb, 0xa5);
  for (uint32_t j = 0; j < h + 2; ++j)
    for (uint32_t i = 0; i < w + 2; ++i) {
      const uint32_t ci = std::clamp<uint32_t>(i, 1, w) - 1, cj = std::clamp<uint32_t>(j, 1, h) - 1;
      std::memcpy(&page[((size_t(y) + j) * pageWidth + x + i) * tb], &t[(size_t(cj) * w + ci) * tb], tb);
    }
  return page;
}

bool isPyramid(const std::vector<uint8_t>& blob) { return blob.size() > 4 && std::memcmp(blob.data(), "PYR1", 4) == 0; }

TEST(TileCodec, EveryTileDecodesToItsBytesInEitherForm) {
  std::mt19937 rng(7);
  int pyramids = 0, tiles = 0;
  for (TexelLayout L : {kNormalTexels, kColorTexels, kHeightTexels})
    for (int trial = 0; trial < 60; ++trial) {
      const uint32_t w = 1 + rng() % 40, h = 1 + rng() % 40, pw = w + 2 + rng() % 5, ph = h + 2 + rng() % 3;
      const uint32_t x = rng() % (pw - w - 1), y = rng() % (ph - h - 1);
      const size_t tb = size_t(L.texelBytes());
      std::vector<uint8_t> cov;
      std::vector<uint8_t> t = makeTile(w, h, L, trial % 3 == 0 ? 0 : 3.0, trial % 4 == 0 ? 0.3 : 0.02, rng, cov);
      if (trial % 2) snapToPyramid(t.data(), cov.data(), w, h, L, [](const uint8_t*, const uint8_t*) { return true; });
      std::vector<uint8_t> page = withGutter(t, w, h, tb, pw, x, y, ph);
      if (trial % 5 == 4) page[(size_t(y) * pw + x) * tb] ^= 1;  // a gutter that does not repeat: the plain form
      const TileRegion r{x, y, w + 2, h + 2};
      const std::vector<uint8_t> blob = encodeTile(page.data(), pw, r, L);
      pyramids += isPyramid(blob);
      ++tiles;
      std::vector<uint8_t> back(page.size(), 0xa5);
      const Status s = decodeTile(blob, back.data(), pw, r, L);
      ASSERT_TRUE(s.isOk()) << s.message();
      ASSERT_EQ(back, page) << "layout " << L.comps << "x" << L.bytes << " tile " << w << "x" << h << " trial " << trial;
    }
  std::printf("%d of %d tiles coded as pyramids\n", pyramids, tiles);
  EXPECT_GT(pyramids, tiles / 5);
}

// TileForm::kPyramid codes every tile that has a pyramid (a repeating gutter, pyramid levels) as
// the pyramid, also where kSmaller finds LOCO-I smaller, and it decodes to the same bytes.
TEST(TileCodec, PyramidFormCodesEveryTileThatHasOne) {
  std::mt19937 rng(5);
  int forced = 0, tiles = 0;
  for (TexelLayout L : {kNormalTexels, kColorTexels})
    for (int trial = 0; trial < 80; ++trial) {
      const uint32_t w = 1 + rng() % 40, h = 1 + rng() % 40;
      const size_t tb = size_t(L.texelBytes());
      std::vector<uint8_t> cov;
      // No noise on most: smooth ramps, where LOCO-I predicts well.
      std::vector<uint8_t> t = makeTile(w, h, L, trial % 4 == 0 ? 3.0 : 0, 0.02, rng, cov);
      if (trial % 3 == 0) snapToPyramid(t.data(), cov.data(), w, h, L, [](const uint8_t*, const uint8_t*) { return true; });
      std::vector<uint8_t> page = withGutter(t, w, h, tb, w + 2, 0, 0, h + 2);
      const bool gutterRepeats = trial % 7 != 6;
      if (!gutterRepeats) page[0] ^= 1;
      const TileRegion r{0, 0, w + 2, h + 2};
      const std::vector<uint8_t> blob = encodeTile(page.data(), w + 2, r, L, kDefaultTileLevel, TileForm::kPyramid);
      const bool hasPyramid = gutterRepeats && pyramidLevels(w, h) > 0;
      ASSERT_EQ(isPyramid(blob), hasPyramid) << "layout " << L.comps << " tile " << w << "x" << h << " trial " << trial;
      tiles += hasPyramid;
      forced += hasPyramid && !isPyramid(encodeTile(page.data(), w + 2, r, L));
      std::vector<uint8_t> back(page.size(), 0xa5);
      const Status s = decodeTile(blob, back.data(), w + 2, r, L);
      ASSERT_TRUE(s.isOk()) << s.message();
      ASSERT_EQ(back, page) << "layout " << L.comps << " tile " << w << "x" << h << " trial " << trial;
    }
  std::printf("%d of %d tiles with a pyramid were LOCO-I by size\n", forced, tiles);
  EXPECT_GT(forced, 0) << "no tile where the form made a difference";
}

// Snapping moves no covered texel past what `close` allows, leaves holes and the coarsest
// level's even texels alone, and makes the coded tile smaller.
TEST(TileCodec, SnappingStaysWithinItsToleranceAndShrinksTheTile) {
  std::mt19937 rng(11);
  for (TexelLayout L : {kNormalTexels, kColorTexels}) {
    size_t before = 0, after = 0, snappedAll = 0;
    for (int trial = 0; trial < 20; ++trial) {
      const uint32_t w = 8 + rng() % 60, h = 8 + rng() % 60;
      const size_t tb = size_t(L.texelBytes());
      std::vector<uint8_t> cov;
      const std::vector<uint8_t> t = makeTile(w, h, L, 1.0, 0.05, rng, cov);
      std::vector<uint8_t> s = t;
      const uint32_t tol = 3 * L.quantum;
      const size_t snapped = snapToPyramid(s.data(), cov.data(), w, h, L, [&](const uint8_t* a, const uint8_t* b) {
        for (int c = 0; c < L.comps; ++c)
          if (std::abs(int(valueAt(a + c * L.bytes, L.bytes)) - int(valueAt(b + c * L.bytes, L.bytes))) > int(tol))
            return false;
        return true;
      });
      snappedAll += snapped;
      const int levels = pyramidLevels(w, h);
      const uint32_t topStep = 1u << levels;
      for (uint32_t j = 0; j < h; ++j)
        for (uint32_t i = 0; i < w; ++i) {
          const size_t k = (size_t(j) * w + i) * tb;
          if (!cov[size_t(j) * w + i] || (i % topStep == 0 && j % topStep == 0)) {
            ASSERT_EQ(std::memcmp(&s[k], &t[k], tb), 0) << "a hole or a coarsest texel moved";
            continue;
          }
          for (int c = 0; c < L.comps; ++c) {
            const int d = int(valueAt(&s[k + c * L.bytes], L.bytes)) - int(valueAt(&t[k + c * L.bytes], L.bytes));
            ASSERT_LE(std::abs(d), int(tol));
            ASSERT_EQ(valueAt(&s[k + c * L.bytes], L.bytes) % L.quantum, 0u) << "off the quantum";
          }
        }
      const std::vector<uint8_t> p0 = withGutter(t, w, h, tb, w + 2, 0, 0, h + 2), p1 = withGutter(s, w, h, tb, w + 2, 0, 0, h + 2);
      before += encodeTile(p0.data(), w + 2, {0, 0, w + 2, h + 2}, L).size();
      after += encodeTile(p1.data(), w + 2, {0, 0, w + 2, h + 2}, L).size();
    }
    std::printf("layout %dx%d: %zu texels snapped, coded %zu -> %zu bytes\n", L.comps, L.bytes, snappedAll, before, after);
    EXPECT_GT(snappedAll, 0u);
    EXPECT_LT(double(after), 0.8 * double(before));
  }
}

// The payload snapToPyramid hands on is the one encodeTile makes from the snapped texels (the
// pyramid blob compresses it: the blobs are the same bytes only if the payloads are), and it is
// empty where the coverage it was given is not the texels' own.
TEST(TileCodec, SnappedPayloadIsTheOneTheCoderMakes) {
  std::mt19937 rng(23);
  int made = 0, refused = 0;
  for (TexelLayout L : {kNormalTexels, kColorTexels})
    for (int trial = 0; trial < 90; ++trial) {
      const uint32_t w = 1 + rng() % 40, h = 1 + rng() % 40;
      const size_t tb = size_t(L.texelBytes());
      std::vector<uint8_t> cov;
      std::vector<uint8_t> t = makeTile(w, h, L, trial % 3 == 0 ? 0 : 2.0, trial % 4 == 0 ? 0.3 : 0.03, rng, cov);
      // Every sixth tile: a covered texel of zero bytes, or an uncovered one with some.
      const bool mismatch = trial % 6 == 5;
      if (mismatch) {
        const size_t k = rng() % cov.size();
        if (cov[k]) std::memset(&t[k * tb], 0, tb);
        else t[k * tb] = uint8_t(L.quantum);
      }
      const uint32_t tol = (trial % 2 ? 2 : 6) * L.quantum;
      std::vector<uint8_t> payload{1, 2, 3};  // replaced
      snapToPyramid(
          t.data(), cov.data(), w, h, L,
          [&](const uint8_t* a, const uint8_t* b) {
            for (int c = 0; c < L.comps; ++c)
              if (std::abs(int(valueAt(a + c * L.bytes, L.bytes)) - int(valueAt(b + c * L.bytes, L.bytes))) > int(tol))
                return false;
            return true;
          },
          &payload);
      const bool hasPyramid = pyramidLevels(w, h) > 0;
      if (mismatch || !hasPyramid) {
        ASSERT_TRUE(payload.empty()) << "tile " << w << "x" << h << " trial " << trial;
        refused += hasPyramid;
        continue;
      }
      ASSERT_FALSE(payload.empty()) << "tile " << w << "x" << h << " trial " << trial;
      ++made;
      const std::vector<uint8_t> page = withGutter(t, w, h, tb, w + 2, 0, 0, h + 2);
      const TileRegion r{0, 0, w + 2, h + 2};
      for (TileForm form : {TileForm::kPyramid, TileForm::kSmaller})
        ASSERT_EQ(encodeTile(page.data(), w + 2, r, L, kDefaultTileLevel, form, payload),
                  encodeTile(page.data(), w + 2, r, L, kDefaultTileLevel, form))
            << "layout " << L.comps << " tile " << w << "x" << h << " trial " << trial;
      // The coder reads the payload it is given: a changed one codes differently.
      payload.back() ^= 1;
      ASSERT_NE(encodeTile(page.data(), w + 2, r, L, kDefaultTileLevel, TileForm::kPyramid, payload),
                encodeTile(page.data(), w + 2, r, L, kDefaultTileLevel, TileForm::kPyramid));
    }
  std::printf("%d payloads made, %d refused for their coverage\n", made, refused);
  EXPECT_GT(made, 60);
  EXPECT_GT(refused, 5);
}

TEST(TileCodec, UpsampleAveragesCoveredEvenNeighboursOnTheQuantum) {
  // 3 x 3 normals: even texels at the corners and (2, 0)...; the centre averages four.
  const uint32_t w = 3, h = 3;
  std::vector<uint8_t> src(w * h * 4, 0), cov(w * h, 1), dst(src.size());
  auto put = [&](uint32_t i, uint32_t j, uint32_t a, uint32_t b) {
    setValue(&src[(j * w + i) * 4], 2, a);
    setValue(&src[(j * w + i) * 4 + 2], 2, b);
  };
  put(0, 0, 64 * 10, 64 * 20);
  put(2, 0, 64 * 12, 64 * 20);
  put(0, 2, 64 * 10, 64 * 23);
  put(2, 2, 64 * 13, 64 * 20);
  cov[1 * w + 0] = 0;  // a hole between (0, 0) and (0, 2)
  upsampleEven(src.data(), cov.data(), w, h, kNormalTexels, dst.data());
  auto get = [&](uint32_t i, uint32_t j, int c) { return valueAt(&dst[(j * w + i) * 4 + c * 2], 2); };
  EXPECT_EQ(get(1, 0, 0), 64u * 11);                // (10 + 12) / 2
  EXPECT_EQ(get(1, 1, 0), 64u * 11);                // (10 + 12 + 10 + 13) / 4 = 11.25
  EXPECT_EQ(get(1, 1, 1), 64u * 21);                // (20 + 20 + 23 + 20) / 4 = 20.75
  EXPECT_EQ(get(0, 1, 0), 0u);                      // the hole stays empty
  EXPECT_EQ(get(2, 1, 1), 64u * 20);                // (20 + 20) / 2
  EXPECT_EQ(std::memcmp(&dst[0], &src[0], 4), 0);   // even texels copied
}

// upsampleEven against the plain formula, (2 sum + count q) / (2 count q) q, on random tiles with
// holes (so that every count from 0 to 4 occurs) and values up to the top of their bytes, for
// quanta that are powers of two (the multiply-and-shift path) and one that is not.
TEST(TileCodec, UpsampleIsTheRoundedMeanForEveryCountAndQuantum) {
  std::mt19937 rng(5);
  for (const TexelLayout L : {kNormalTexels, kColorTexels, TexelLayout{1, 2, 1}, TexelLayout{3, 2, 3}, TexelLayout{2, 1, 8}}) {
    const uint32_t w = 37, h = 29, top = L.bytes == 2 ? 0xffffu : 0xffu;
    const size_t tb = size_t(L.texelBytes());
    std::vector<uint8_t> src(size_t(w) * h * tb), cov(size_t(w) * h), dst(src.size());
    std::uniform_int_distribution<uint32_t> value(0, top / L.quantum);
    for (size_t k = 0; k < cov.size(); ++k) {
      cov[k] = rng() % 4 != 0;
      for (int c = 0; c < L.comps; ++c) setValue(&src[k * tb + size_t(c) * L.bytes], L.bytes, value(rng) * L.quantum);
    }
    upsampleEven(src.data(), cov.data(), w, h, L, dst.data());
    size_t byCount[5] = {};
    for (uint32_t j = 0; j < h; ++j)
      for (uint32_t i = 0; i < w; ++i) {
        const size_t k = size_t(j) * w + i;
        if ((i % 2 == 0 && j % 2 == 0) || !cov[k]) continue;
        for (int c = 0; c < L.comps; ++c) {
          uint32_t sum = 0, count = 0;
          for (int dj = -int(j % 2); dj <= int(j % 2); dj += 2)
            for (int di = -int(i % 2); di <= int(i % 2); di += 2) {
              const int x = int(i) + di, y = int(j) + dj;
              if (x < 0 || y < 0 || x >= int(w) || y >= int(h) || !cov[size_t(y) * w + size_t(x)]) continue;
              sum += valueAt(&src[(size_t(y) * w + size_t(x)) * tb + size_t(c) * L.bytes], L.bytes);
              ++count;
            }
          if (c == 0) ++byCount[count];
          uint32_t want = count ? (2 * sum + count * L.quantum) / (2 * count * L.quantum) * L.quantum : 0;
          if (want > top) want -= L.quantum;
          ASSERT_EQ(valueAt(&dst[k * tb + size_t(c) * L.bytes], L.bytes), want)
              << "texel (" << i << ", " << j << ") component " << c << ", quantum " << L.quantum << ", count " << count;
        }
      }
    for (int n = 0; n <= 4; ++n) EXPECT_GT(byCount[n], 0u) << "no texel averaged " << n << " neighbours";
  }
}

TEST(TileCodec, DamagedPyramidBlobsAreErrors) {
  std::mt19937 rng(3);
  const uint32_t w = 20, h = 17;
  std::vector<uint8_t> cov;
  std::vector<uint8_t> t = makeTile(w, h, kNormalTexels, 1.0, 0.0, rng, cov);
  snapToPyramid(t.data(), cov.data(), w, h, kNormalTexels, [](const uint8_t*, const uint8_t*) { return true; });
  const std::vector<uint8_t> page = withGutter(t, w, h, 4, w + 2, 0, 0, h + 2);
  const TileRegion r{0, 0, w + 2, h + 2};
  std::vector<uint8_t> blob = encodeTile(page.data(), w + 2, r, kNormalTexels);
  ASSERT_TRUE(isPyramid(blob));
  std::vector<uint8_t> out(page.size());
  EXPECT_FALSE(decodeTile(std::span(blob).first(blob.size() - 3), out.data(), w + 2, r, kNormalTexels).isOk());
  EXPECT_FALSE(decodeTile(blob, out.data(), w + 3, {0, 0, w + 3, h + 2}, kNormalTexels).isOk()) << "another tile size";
  EXPECT_FALSE(decodeTile(std::span(blob).first(4), out.data(), w + 2, r, kNormalTexels).isOk()) << "the tag alone";
  const Status s = decodeTile(blob, out.data(), 3, {0, 0, 3, 3}, kNormalTexels);
  EXPECT_FALSE(s.isOk());
}


// A w x h tile with its gutter: a height ramp with noise, holes where `hole` says, random unit
// normals and colours on the covered texels; the gutter repeats the edge (as packs store it).
TileImage randomTile(uint32_t w, uint32_t h, std::mt19937& rng, double hole) {
  TileImage t = blankTile(w, h, true, true);
  std::uniform_real_distribution<double> u(0, 1);
  for (uint32_t j = 0; j < h; ++j)
    for (uint32_t i = 0; i < w; ++i) {
      if (u(rng) < hole) continue;
      const size_t o = size_t(j + 1) * (w + 2) + i + 1;
      t.heights[o] = uint16_t(1 + std::min(65000.0, 300.0 * i + 200.0 * j + 400 * u(rng)));
      encodeNormal(u(rng) - 0.5, u(rng) - 0.5, 1.0, &t.normals[o * kNormalBytes]);
      for (int c = 0; c < 4; ++c) t.rgba[o * 4 + c] = uint8_t(rng());
    }
  // The gutter: edge texels repeated.
  auto copy = [&](uint32_t fi, uint32_t fj, uint32_t ti, uint32_t tj) {
    const size_t f = size_t(fj) * (w + 2) + fi, d = size_t(tj) * (w + 2) + ti;
    t.heights[d] = t.heights[f];
    std::memcpy(&t.normals[d * kNormalBytes], &t.normals[f * kNormalBytes], kNormalBytes);
    std::memcpy(&t.rgba[d * 4], &t.rgba[f * 4], 4);
  };
  for (uint32_t i = 1; i <= w; ++i) copy(i, 1, i, 0), copy(i, h, i, h + 1);
  for (uint32_t j = 0; j < h + 2; ++j) copy(1, std::clamp<uint32_t>(j, 1, h), 0, j), copy(w, std::clamp<uint32_t>(j, 1, h), w + 1, j);
  return t;
}

// What a pack stores beside a tile (MIPZ) decodes to the very level coarserLevel builds from the
// tile: a reader may take either. Tiles too small to have the level store none.
TEST(TileLevels, StoredLevelsAreTheLevelsBuiltFromTheTile) {
  std::mt19937 rng(11);
  const uint32_t sizes[][2] = {{1, 1}, {15, 9}, {16, 16}, {17, 3}, {37, 21}, {70, 70}, {129, 64}, {300, 5}};
  for (const auto& sz : sizes)
    for (double hole : {0.0, 0.3, 0.9}) {
      const TileImage t = randomTile(sz[0], sz[1], rng, hole);
      const std::vector<uint8_t> blob = encodeStoredLevels(t, kDefaultTileLevel);
      const uint32_t levels = levelCount(sz[0], sz[1]);
      std::vector<TileImage> built{t};
      while (built.back().w > 1 || built.back().h > 1) built.push_back(coarserLevel(built.back()));
      ASSERT_EQ(built.size(), levels);
      uint32_t stored = 0;
      for (uint32_t l : kStoredLevels) {
        if (l >= levels) {
          EXPECT_EQ(storedLevelAtMost(blob, l), stored) << sz[0] << "x" << sz[1] << ": no level " << l;
          continue;
        }
        stored = l;
        EXPECT_EQ(storedLevelAtMost(blob, l), l);
        EXPECT_EQ(storedLevelAtMost(blob, l + 3), l);
        EXPECT_EQ(storedLevelAtMost(blob, l - 1), 0u);
        TileImage got;
        ASSERT_TRUE(decodeStoredLevel(blob, sz[0], sz[1], l, true, true, got).isOk());
        EXPECT_EQ(got.w, built[l].w);
        EXPECT_EQ(got.h, built[l].h);
        EXPECT_EQ(got.heights, built[l].heights) << sz[0] << "x" << sz[1] << " level " << l << " holes " << hole;
        EXPECT_EQ(got.normals, built[l].normals);
        EXPECT_EQ(got.rgba, built[l].rgba);
        EXPECT_EQ(got.cover, built[l].cover);
        EXPECT_EQ(got.cover.size(), got.heights.size()) << "a stored level has its coverage masks";
        // The pack's channels must match the blob's.
        EXPECT_FALSE(decodeStoredLevel(blob, sz[0], sz[1], l, false, true, got).isOk());
        EXPECT_FALSE(decodeStoredLevel(blob, sz[0] + 16, sz[1], l, true, true, got).isOk()) << "another tile's size";
      }
      if (!stored) {
        EXPECT_EQ(blob.size(), 4u) << "a tile with none of the levels stores a count of 0";
      }
    }
}

// Packs before pipeline revision 15 stored levels without coverage masks (no kStoredCover in the
// count word): they decode as they were, a covered texel covered throughout.
TEST(TileLevels, StoredLevelsWithoutMasksStillDecode) {
  std::mt19937 rng(9);
  TileImage t = randomTile(64, 48, rng, 0.3);
  const uint32_t l = kStoredLevels[0];
  for (uint32_t k = 0; k < l; ++k) t = coarserLevel(t);
  const TileRegion inside{1, 1, t.w, t.h};
  const std::vector<TilePlane> planes{{reinterpret_cast<uint8_t*>(t.heights.data()), t.w + 2, inside, kHeightTexels},
                                      {t.normals.data(), t.w + 2, inside, kNormalTexels},
                                      {t.rgba.data(), t.w + 2, inside, kColorTexels}};
  const std::vector<uint8_t> frame = encodeTilePlanes(planes);
  const uint32_t head[3] = {1, l, uint32_t(frame.size())};
  std::vector<uint8_t> blob(sizeof head);
  std::memcpy(blob.data(), head, sizeof head);
  blob.insert(blob.end(), frame.begin(), frame.end());
  EXPECT_EQ(storedLevelAtMost(blob, 31), l);
  TileImage got;
  ASSERT_TRUE(decodeStoredLevel(blob, 64, 48, l, true, true, got).isOk());
  EXPECT_EQ(got.heights, t.heights);
  EXPECT_TRUE(got.cover.empty());
  const std::vector<uint8_t> masked = encodeStoredLevels(randomTile(64, 48, rng, 0.3), kDefaultTileLevel);
  uint32_t word = 0;
  std::memcpy(&word, masked.data(), 4);
  EXPECT_EQ(word, 1u | kStoredCover);
}

// A damaged blob is an error naming what is wrong, never a crash or a read past it.
TEST(TileLevels, DamagedStoredLevelsAreErrors) {
  std::mt19937 rng(5);
  const TileImage t = randomTile(64, 48, rng, 0.1);
  const std::vector<uint8_t> blob = encodeStoredLevels(t, kDefaultTileLevel);
  const uint32_t l = kStoredLevels[0];
  TileImage got;
  ASSERT_TRUE(decodeStoredLevel(blob, 64, 48, l, true, true, got).isOk());
  EXPECT_FALSE(decodeStoredLevel(blob, 64, 48, l + 1, true, true, got).isOk()) << "a level not stored";
  for (size_t cut : {size_t(0), size_t(3), size_t(7), blob.size() / 2, blob.size() - 1}) {
    const std::span<const uint8_t> part(blob.data(), cut);
    EXPECT_FALSE(decodeStoredLevel(part, 64, 48, l, true, true, got).isOk()) << "cut at " << cut;
    EXPECT_EQ(storedLevelAtMost(part, 31), 0u) << "a header whose frame does not fit";
  }
  std::vector<uint8_t> bad = blob;
  bad[0] = 200;  // the count
  EXPECT_FALSE(decodeStoredLevel(bad, 64, 48, l, true, true, got).isOk());
  EXPECT_EQ(storedLevelAtMost(bad, 31), 0u);
  for (size_t k = 12; k < blob.size(); k += 7) {  // the frame: an error or some texels, never a crash
    bad = blob;
    bad[k] ^= 0x5a;
    (void)decodeStoredLevel(bad, 64, 48, l, true, true, got);
  }
}

// The normal encoder's rounding is std::round's: at and beside every half, at the largest
// double below one half, on random values, and (through std::round) outside its range.
TEST(PackFormat, RoundNonNegativeIsStdRound) {
  std::vector<double> v = {0.0, 0.49999999999999994, 0.5, 1.5, 2.5, 1023.5, 4503599627370495.5, 4503599627370496.0,
                           -0.5, -2.5, 1e300, std::numeric_limits<double>::infinity()};
  for (int k = 0; k <= 2048; ++k) {
    const double h = k + 0.5;
    v.insert(v.end(), {h, std::nextafter(h, 0.0), std::nextafter(h, 1e9), double(k)});
  }
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(0, 1100);
  for (int k = 0; k < 100000; ++k) v.push_back(u(rng));
  for (const double x : v) {
    EXPECT_EQ(roundNonNegative(x), std::round(x)) << x;
    if (std::abs(x) < 1e18) {
      EXPECT_EQ(lroundNonNegative(x), std::lround(x)) << x;
    }
  }
  EXPECT_TRUE(std::isnan(roundNonNegative(std::nan(""))));
}

}  // namespace
}  // namespace sa
