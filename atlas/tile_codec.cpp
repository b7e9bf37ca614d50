#include "atlas/tile_codec.h"

#include <zstd.h>

#include <algorithm>
#include <bit>
#include <cstdlib>
#include <cstring>

#include "atlas/zstd_context.h"
#include "common/raw_vector.h"

namespace sa {
namespace {

// LOCO-I's median edge detector: a left, b up, c up-left. min(a, b) where c >= max(a, b),
// max(a, b) where c <= min(a, b), else a + b - c: that is a + b - c clamped to [min, max] (c at
// or above the max puts a + b - c at or below the min, and the other way), without branches, so
// the encoder's rows are coded in vector lanes. Components have at most 16 bits.
inline uint32_t predict(uint32_t a, uint32_t b, uint32_t c) {
  const int lo = int(std::min(a, b)), hi = int(std::max(a, b));
  return uint32_t(std::clamp(int(a) + int(b) - int(c), lo, hi));
}

// The prediction of texel i of a row from the row (cur, known left of i) and the one above
// (prev; null on the first row). Two rows, not the tile: a hostile tile size costs no more
// than the tile's own bytes.
inline uint32_t predictAt(const uint32_t* cur, const uint32_t* prev, uint32_t i) {
  if (!prev) return i ? cur[i - 1] : 0;
  if (i == 0) return prev[0];
  return predict(cur[i - 1], prev[i], prev[i - 1]);
}

uint32_t readValue(const uint8_t* p, int bytes) { return bytes == 2 ? uint32_t(p[0]) | uint32_t(p[1]) << 8 : p[0]; }

// One component's residual planes (lo, hi: its low and high bytes; hi unused for one byte),
// compiled for its width:
// the first row and column apart, the rest without a test per texel.
template <int Bytes>
void residualComponent(const uint8_t* page, uint32_t pageWidth, TileRegion r, size_t tb, int c, uint32_t* rows,
                       uint8_t* lo, uint8_t* hi) {
  constexpr uint32_t mask = Bytes == 2 ? 0xffffu : 0xffu;
  for (uint32_t j = 0; j < r.h; ++j) {
    uint32_t* cur = rows + size_t(j & 1) * r.w;
    const uint32_t* prev = j ? rows + size_t((j - 1) & 1) * r.w : nullptr;
    const uint8_t* row = page + ((size_t(r.y) + j) * pageWidth + r.x) * tb + size_t(c) * Bytes;
    for (uint32_t i = 0; i < r.w; ++i) cur[i] = readValue(row + i * tb, Bytes);
    uint8_t* l = lo + size_t(j) * r.w;
    uint8_t* h = Bytes == 2 ? hi + size_t(j) * r.w : nullptr;
    auto put = [&](uint32_t i, uint32_t predicted) {
      const uint32_t res = (cur[i] - predicted) & mask;
      l[i] = uint8_t(res);
      if (Bytes == 2) h[i] = uint8_t(res >> 8);
    };
    if (!prev) {
      for (uint32_t i = 0; i < r.w; ++i) put(i, i ? cur[i - 1] : 0);
      continue;
    }
    if (r.w) put(0, prev[0]);
    for (uint32_t i = 1; i < r.w; ++i) put(i, predict(cur[i - 1], prev[i], prev[i - 1]));
  }
}

// The residual byte planes of region r of `page`: component after component, low bytes first
// (the high bytes of small residuals are runs of 0x00 and 0xff).
std::vector<uint8_t> residualPlanes(const uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout) {
  const size_t n = size_t(r.w) * r.h, tb = size_t(layout.texelBytes());
  std::vector<uint8_t> planes(n * tb);
  std::vector<uint32_t> rows(2 * size_t(r.w));
  for (int c = 0; c < layout.comps; ++c) {
    uint8_t* lo = planes.data() + size_t(c) * layout.bytes * n;
    if (layout.bytes == 2) residualComponent<2>(page, pageWidth, r, tb, c, rows.data(), lo, lo + n);
    else residualComponent<1>(page, pageWidth, r, tb, c, rows.data(), lo, nullptr);
  }
  return planes;
}

// The inverse: region r of `page` from its residual planes.
void applyPlanes(const uint8_t* planes, uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout) {
  const size_t n = size_t(r.w) * r.h, tb = size_t(layout.texelBytes());
  const uint32_t mask = layout.bytes == 2 ? 0xffffu : 0xffu;
  std::vector<uint32_t> rows(2 * size_t(r.w));
  for (int c = 0; c < layout.comps; ++c) {
    const uint8_t* lo = planes + size_t(c) * layout.bytes * n;
    const uint8_t* hi = lo + n;
    for (uint32_t j = 0; j < r.h; ++j) {
      uint32_t* cur = rows.data() + size_t(j & 1) * r.w;
      const uint32_t* prev = j ? rows.data() + size_t((j - 1) & 1) * r.w : nullptr;
      uint8_t* row = page + ((size_t(r.y) + j) * pageWidth + r.x) * tb + size_t(c) * layout.bytes;
      for (uint32_t i = 0; i < r.w; ++i) {
        const size_t k = size_t(j) * r.w + i;
        const uint32_t res = layout.bytes == 2 ? uint32_t(lo[k]) | uint32_t(hi[k]) << 8 : lo[k];
        cur[i] = (predictAt(cur, prev, i) + res) & mask;
        row[i * tb] = uint8_t(cur[i]);
        if (layout.bytes == 2) row[i * tb + 1] = uint8_t(cur[i] >> 8);
      }
    }
  }
}

// The shortest match zstd looks for in a tile's bytes (its levels' own: 4 or 5 under 256 KB).
// Residual planes and pyramid payloads are mostly runs and small values, whose short matches
// cost about what their literals do; searching only for 6 bytes and more gave fewer bytes and
// less time at every level from 1 to 12 on the coded tiles of the 2 M-point survey, lone-star,
// the dragon mesh and the bunny's scans (level 6: 0.4-1.9 % fewer bytes, 8-16 % less time).
// Above level 12 zstd's optimal parsers weigh each match's cost themselves (there 6 gave 0.1-0.2 %
// more bytes): they keep their own.
constexpr int kTileMinMatch = 6, kTileMinMatchUpTo = 12;

std::vector<uint8_t> compress(std::span<const uint8_t> bytes, int level, size_t skip = 0) {
  std::vector<uint8_t> out(skip + ZSTD_compressBound(bytes.size()));
  ZSTD_CCtx* c = threadZstd().c;
  ZSTD_CCtx_reset(c, ZSTD_reset_session_and_parameters);
  ZSTD_CCtx_setParameter(c, ZSTD_c_compressionLevel, level);
  if (level <= kTileMinMatchUpTo) ZSTD_CCtx_setParameter(c, ZSTD_c_minMatch, kTileMinMatch);
  const size_t z = ZSTD_compress2(c, out.data() + skip, out.size() - skip, bytes.data(), bytes.size());
  out.resize(ZSTD_isError(z) ? 0 : skip + z);  // cannot fail: the bound holds
  return out;
}

// One texel's tb bytes copied, zeroed, compared. Texels are 2 or 4 bytes (coverage masks 1), and
// a size known here is one move; a memcpy call of a run-time size cost more than the copy.
inline void copyTexel(uint8_t* d, const uint8_t* s, size_t tb) {
  if (tb == 4) std::memcpy(d, s, 4);
  else if (tb == 2) std::memcpy(d, s, 2);
  else if (tb == 1) *d = *s;
  else std::memcpy(d, s, tb);
}
inline void zeroTexel(uint8_t* d, size_t tb) {
  if (tb == 4) std::memset(d, 0, 4);
  else if (tb == 2) std::memset(d, 0, 2);
  else std::memset(d, 0, tb);
}
inline bool sameTexel(const uint8_t* a, const uint8_t* b, size_t tb) {
  if (tb == 4) return std::memcmp(a, b, 4) == 0;
  if (tb == 2) return std::memcmp(a, b, 2) == 0;
  return std::memcmp(a, b, tb) == 0;
}

// A pyramid blob: this tag, then one zstd frame (FORMAT.md, "Compressed pages").
constexpr uint8_t kPyramidTag[4] = {'P', 'Y', 'R', '1'};

// The tile of region r without its gutter, when the gutter repeats the tile's edge (corners
// included) as every writer's does; empty otherwise.
std::vector<uint8_t> interiorOf(const uint8_t* page, uint32_t pageWidth, TileRegion r, size_t tb) {
  const uint32_t iw = r.w - 2, ih = r.h - 2;
  std::vector<uint8_t> in(size_t(iw) * ih * tb);
  for (uint32_t j = 0; j < ih; ++j)
    std::memcpy(in.data() + size_t(j) * iw * tb, page + ((size_t(r.y) + j + 1) * pageWidth + r.x + 1) * tb, iw * tb);
  for (uint32_t j = 0; j < r.h; ++j)
    for (uint32_t i = 0; i < r.w; i += (j == 0 || j == r.h - 1 || i == r.w - 1) ? 1 : r.w - 1) {  // the border only
      const uint32_t ci = std::clamp<uint32_t>(i, 1, iw) - 1, cj = std::clamp<uint32_t>(j, 1, ih) - 1;
      const uint8_t* p = page + ((size_t(r.y) + j) * pageWidth + r.x + i) * tb;
      if (!sameTexel(in.data() + (size_t(cj) * iw + ci) * tb, p, tb)) return {};
    }
  return in;
}

// Texel (i, j) of level l of a pyramid over a w-texel-wide tile: tile texel (i 2^l, j 2^l).
struct Level {
  uint32_t w, h, step;
};

std::vector<Level> levelsOf(uint32_t w, uint32_t h) {
  std::vector<Level> lv{{w, h, 1}};
  for (int l = pyramidLevels(w, h); l > 0; --l) {
    const Level& f = lv.back();
    lv.push_back({(f.w + 1) / 2, (f.h + 1) / 2, f.step * 2});
  }
  return lv;
}

// Level `L` of tile `t` (w wide) as a tight grid, and back. The texel size is a template
// argument for the sizes tiles have (1: coverage, 2: heights, 4: normals and colours): one move
// a texel instead of a test of the size.
template <size_t TB>
void gatherAs(const uint8_t* t, uint32_t w, Level L, size_t tb, uint8_t* g) {
  const size_t n = TB ? TB : tb;
  for (uint32_t j = 0; j < L.h; ++j) {
    const uint8_t* row = t + size_t(j) * L.step * w * n;
    uint8_t* out = g + size_t(j) * L.w * n;
    for (uint32_t i = 0; i < L.w; ++i) std::memcpy(out + size_t(i) * n, row + size_t(i) * L.step * n, TB ? TB : n);
  }
}
void gather(const uint8_t* t, uint32_t w, Level L, size_t tb, uint8_t* g) {
  if (tb == 1) return gatherAs<1>(t, w, L, tb, g);
  if (tb == 2) return gatherAs<2>(t, w, L, tb, g);
  if (tb == 4) return gatherAs<4>(t, w, L, tb, g);
  gatherAs<0>(t, w, L, tb, g);
}
void scatter(const uint8_t* g, Level L, uint32_t w, size_t tb, uint8_t* t) {
  for (uint32_t j = 0; j < L.h; ++j)
    for (uint32_t i = 0; i < L.w; ++i)
      copyTexel(t + (size_t(j) * L.step * w + size_t(i) * L.step) * tb, g + (size_t(j) * L.w + i) * tb, tb);
}

// One level as a tight grid: its values, its coverage and its rebuild from the level above
// (upsampleEven over the grid). Made without zeroing: levelOf writes every byte of each.
struct LevelGrids {
  RawVector<uint8_t> values, cov, rebuilt;
};

// The texels of level L that are not on the level above (not at an even column and row).
size_t oddCount(Level L) { return size_t(L.w) * L.h - size_t((L.w + 1) / 2) * ((L.h + 1) / 2); }

// Level L of a w-wide tile and its coverage, and the level's rebuild from the one above.
LevelGrids levelOf(const uint8_t* tile, const uint8_t* cov, uint32_t w, Level L, TexelLayout layout) {
  const size_t tb = size_t(layout.texelBytes());
  LevelGrids g;
  g.values.resize(size_t(L.w) * L.h * tb);
  g.cov.resize(size_t(L.w) * L.h);
  g.rebuilt.resize(g.values.size());
  gather(tile, w, L, tb, g.values.data());
  gather(cov, w, L, 1, g.cov.data());
  upsampleEven(g.values.data(), g.cov.data(), L.w, L.h, layout, g.rebuilt.data());
  return g;
}

// The residuals of a level's texels that are not even/even (row-major) against the rebuild,
// byte planes as residualPlanes'; applyOdd is the inverse.
void encodeOdd(const LevelGrids& g, Level L, TexelLayout layout, std::vector<uint8_t>& out) {
  const size_t tb = size_t(layout.texelBytes()), odd = oddCount(L);
  const uint32_t mask = layout.bytes == 2 ? 0xffffu : 0xffu;
  const size_t base = out.size();
  out.resize(base + odd * tb);
  for (int c = 0; c < layout.comps; ++c) {
    uint8_t* lo = out.data() + base + size_t(c) * layout.bytes * odd;
    uint8_t* hi = lo + odd;
    size_t o = 0;
    for (uint32_t j = 0; j < L.h; ++j)
      for (uint32_t i = 1 - (j & 1); i < L.w; i += 2 - (j & 1)) {  // even rows: odd columns; odd rows: all
        const size_t at = (size_t(j) * L.w + i) * tb + size_t(c) * layout.bytes;
        const uint32_t res = (readValue(&g.values[at], layout.bytes) - readValue(&g.rebuilt[at], layout.bytes)) & mask;
        lo[o] = uint8_t(res);
        if (layout.bytes == 2) hi[o] = uint8_t(res >> 8);
        ++o;
      }
  }
}
void applyOdd(const uint8_t* planes, Level L, TexelLayout layout, LevelGrids& g) {
  const size_t tb = size_t(layout.texelBytes()), odd = oddCount(L);
  const uint32_t mask = layout.bytes == 2 ? 0xffffu : 0xffu;
  for (int c = 0; c < layout.comps; ++c) {
    const uint8_t* lo = planes + size_t(c) * layout.bytes * odd;
    const uint8_t* hi = lo + odd;
    size_t o = 0;
    for (uint32_t j = 0; j < L.h; ++j)
      for (uint32_t i = 1 - (j & 1); i < L.w; i += 2 - (j & 1)) {  // as encodeOdd
        const size_t at = (size_t(j) * L.w + i) * tb + size_t(c) * layout.bytes;
        const uint32_t res = layout.bytes == 2 ? uint32_t(lo[o]) | uint32_t(hi[o]) << 8 : lo[o];
        const uint32_t v = (readValue(&g.rebuilt[at], layout.bytes) + res) & mask;
        g.values[at] = uint8_t(v);
        if (layout.bytes == 2) g.values[at + 1] = uint8_t(v >> 8);
        ++o;
      }
  }
}

// The pyramid payload's head: the coverage mask (a bit a texel, row-major) and the coarsest
// level's residual planes.
std::vector<uint8_t> pyramidHead(const uint8_t* in, const uint8_t* cov, uint32_t iw, uint32_t ih,
                                 const std::vector<Level>& lv, TexelLayout layout) {
  const size_t tb = size_t(layout.texelBytes()), n = size_t(iw) * ih;
  std::vector<uint8_t> payload((n + 7) / 8, 0);
  for (size_t k = 0; k < n; ++k) payload[k / 8] |= uint8_t(uint8_t(cov[k] != 0) << (k % 8));
  const Level& top = lv.back();
  std::vector<uint8_t> grid(size_t(top.w) * top.h * tb);
  gather(in, iw, top, tb, grid.data());
  const std::vector<uint8_t> coarse = residualPlanes(grid.data(), top.w, {0, 0, top.w, top.h}, layout);
  payload.insert(payload.end(), coarse.begin(), coarse.end());
  return payload;
}

// Whether a texel is covered as the pyramid's mask has it: any byte not zero.
std::vector<uint8_t> coverOf(const uint8_t* in, size_t n, size_t tb) {
  std::vector<uint8_t> cov(n);
  for (size_t k = 0; k < n; ++k) cov[k] = std::any_of(in + k * tb, in + (k + 1) * tb, [](uint8_t b) { return b != 0; });
  return cov;
}

// The pyramid payload of region r, before zstd (empty for a tile too small for a level or a
// gutter that does not repeat the tile): the head, then each finer level's other texels against
// their rebuild from the level above.
std::vector<uint8_t> pyramidPayload(const uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout) {
  if (r.w < 3 || r.h < 3) return {};
  const size_t tb = size_t(layout.texelBytes());
  const std::vector<uint8_t> in = interiorOf(page, pageWidth, r, tb);
  const uint32_t iw = r.w - 2, ih = r.h - 2;
  const std::vector<Level> lv = levelsOf(iw, ih);
  if (in.empty() || lv.size() < 2) return {};
  const std::vector<uint8_t> cov = coverOf(in.data(), size_t(iw) * ih, tb);
  std::vector<uint8_t> payload = pyramidHead(in.data(), cov.data(), iw, ih, lv, layout);
  for (size_t l = lv.size() - 1; l-- > 0;) {
    LevelGrids g = levelOf(in.data(), cov.data(), iw, lv[l], layout);
    encodeOdd(g, lv[l], layout, payload);
  }
  return payload;
}

// The pyramid blob: the tag, then the payload's zstd frame.
std::vector<uint8_t> pyramidBlob(std::span<const uint8_t> payload, int level) {
  std::vector<uint8_t> out = compress(payload, level, sizeof kPyramidTag);
  std::copy(std::begin(kPyramidTag), std::end(kPyramidTag), out.begin());
  return out;
}

// Bytes at zstd's fastest level. Which of two payloads codes smaller there agrees with the
// pack's level on all but 1.3 % of the normal and colour tiles of the real scans and the survey;
// a pack's normal and colour bytes grew by at most 0.043 % (docs/BENCHMARKS.md). Coding both
// forms at the pack's level took about 4 % more of a pack's CPU.
size_t quickSize(std::span<const uint8_t> bytes) {
  thread_local std::vector<uint8_t> scratch;
  scratch.resize(ZSTD_compressBound(bytes.size()));
  return ZSTD_compressCCtx(threadZstd().c, scratch.data(), scratch.size(), bytes.data(), bytes.size(), 1);
}

// Reads one zstd frame of exactly `want` bytes.
Status decompressExactly(std::span<const uint8_t> blob, size_t want, std::vector<uint8_t>& out) {
  const unsigned long long declared = ZSTD_getFrameContentSize(blob.data(), blob.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR || declared == ZSTD_CONTENTSIZE_UNKNOWN)
    return Status::badInput("not a zstd frame with its size");
  if (declared != want)
    return Status::badInput("holds " + std::to_string(declared) + " bytes, the tile needs " + std::to_string(want));
  out.resize(want);
  const size_t got = ZSTD_decompressDCtx(threadZstd().d, out.data(), out.size(), blob.data(), blob.size());
  if (ZSTD_isError(got)) return Status::badInput(std::string("damaged (") + ZSTD_getErrorName(got) + ")");
  if (got != out.size()) return Status::badInput("decodes to fewer bytes than its frame says");
  return Status::ok();
}

Status decodePyramid(std::span<const uint8_t> blob, uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout) {
  if (r.w < 3 || r.h < 3) return Status::badInput("a pyramid blob for a tile under one texel");
  const size_t tb = size_t(layout.texelBytes());
  const uint32_t iw = r.w - 2, ih = r.h - 2;
  const std::vector<Level> lv = levelsOf(iw, ih);
  if (lv.size() < 2) return Status::badInput("a pyramid blob for a tile too small for one");
  const size_t n = size_t(iw) * ih, maskBytes = (n + 7) / 8;
  std::vector<uint8_t> payload;
  SA_RETURN_IF_ERROR(decompressExactly(blob.subspan(sizeof kPyramidTag), maskBytes + n * tb, payload));
  std::vector<uint8_t> in(n * tb, 0), cov(n);
  for (size_t k = 0; k < n; ++k) cov[k] = (payload[k / 8] >> (k % 8)) & 1;
  const Level& top = lv.back();
  std::vector<uint8_t> grid(size_t(top.w) * top.h * tb);
  applyPlanes(payload.data() + maskBytes, grid.data(), top.w, {0, 0, top.w, top.h}, layout);
  scatter(grid.data(), top, iw, tb, in.data());
  size_t at = maskBytes + grid.size();
  for (size_t l = lv.size() - 1; l-- > 0;) {
    LevelGrids g = levelOf(in.data(), cov.data(), iw, lv[l], layout);
    applyOdd(payload.data() + at, lv[l], layout, g);
    at += oddCount(lv[l]) * tb;
    scatter(g.values.data(), lv[l], iw, tb, in.data());
  }
  for (uint32_t j = 0; j < r.h; ++j)
    for (uint32_t i = 0; i < r.w; ++i) {
      const uint32_t ci = std::clamp<uint32_t>(i, 1, iw) - 1, cj = std::clamp<uint32_t>(j, 1, ih) - 1;
      copyTexel(page + ((size_t(r.y) + j) * pageWidth + r.x + i) * tb, in.data() + (size_t(cj) * iw + ci) * tb, tb);
    }
  return Status::ok();
}

}  // namespace

int pyramidLevels(uint32_t w, uint32_t h) {
  int l = 0;
  for (; l < kMaxPyramidLevels && w >= 4 && h >= 4; ++l) {
    w = (w + 1) / 2;
    h = (h + 1) / 2;
  }
  return l;
}

namespace {

// x / count for count 0 to 4 as (x * mul) >> shift, exact for every 32-bit x (0xAAAAAAAB =
// ceil(2^33 / 3)); 0 for count 0.
struct ByCount {
  uint64_t mul;
  int shift;
};
constexpr ByCount kByCount[5] = {{0, 0}, {1, 0}, {1, 1}, {0xAAAAAAABull, 33}, {1, 2}};

// upsampleEven for a layout of Comps components of Bytes bytes each, known when compiled: the
// per-component loops unroll (the pyramids' rebuilds were 3.3 % of a pack's CPU).
template <int Comps, int Bytes>
void upsampleEvenAs(const uint8_t* src, const uint8_t* covered, uint32_t w, uint32_t h, uint32_t quantum, uint8_t* dst) {
  constexpr size_t tb = size_t(Comps) * Bytes;
  constexpr uint32_t top = Bytes == 2 ? 0xffffu : 0xffu;
  const uint32_t q = std::max(quantum, 1u);
  const bool pow2 = (q & (q - 1)) == 0;
  const int s = std::countr_zero(q) + 1;  // 2q = 2^s where q is a power of two
  for (uint32_t j = 0; j < h; ++j)
    for (uint32_t i = 0; i < w; ++i) {
      const size_t k = size_t(j) * w + i;
      uint8_t* d = dst + k * tb;
      if (!(i & 1) && !(j & 1)) {
        copyTexel(d, src + k * tb, tb);
        continue;
      }
      if (!covered[k]) {
        zeroTexel(d, tb);
        continue;
      }
      uint32_t sum[Comps] = {}, count = 0;
      const int oi = int(i & 1), oj = int(j & 1);
      for (int dj = -oj; dj <= oj; dj += 2)
        for (int di = -oi; di <= oi; di += 2) {
          const int64_t x = int64_t(i) + di, y = int64_t(j) + dj;
          if (x < 0 || y < 0 || x >= int64_t(w) || y >= int64_t(h)) continue;
          const size_t m = size_t(y) * w + size_t(x);
          if (!covered[m]) continue;
          for (int c = 0; c < Comps; ++c) sum[c] += readValue(src + m * tb + size_t(c) * Bytes, Bytes);
          ++count;
        }
      for (int c = 0; c < Comps; ++c) {
        // The nearest multiple, ties up: (2 sum + count q) / (2 count q), times q. With q a power
        // of two, 2q = 2^s: the quotient is ((2 sum + count q) >> s) / count, and the division
        // by count (0 to 4) a multiply and shift (timed alone on 64 random tiles: 3 % faster for
        // normals, 7 % for colours).
        const uint32_t n = 2 * sum[c] + count * q;
        uint32_t v = pow2 ? uint32_t((uint64_t(n >> s) * kByCount[count].mul) >> kByCount[count].shift) * q
                          : (count ? n / (2 * count * q) * q : 0);
        if (v > top) v -= q;
        d[size_t(c) * Bytes] = uint8_t(v);
        if (Bytes == 2) d[size_t(c) * Bytes + 1] = uint8_t(v >> 8);
      }
    }
}

}  // namespace

void upsampleEven(const uint8_t* src, const uint8_t* covered, uint32_t w, uint32_t h, TexelLayout layout, uint8_t* dst) {
  const uint32_t q = layout.quantum;
  switch (layout.comps * 4 + layout.bytes) {  // the layouts a tile can have: 1 to 4 components of 1 or 2 bytes
    case 1 * 4 + 1: return upsampleEvenAs<1, 1>(src, covered, w, h, q, dst);
    case 1 * 4 + 2: return upsampleEvenAs<1, 2>(src, covered, w, h, q, dst);
    case 2 * 4 + 1: return upsampleEvenAs<2, 1>(src, covered, w, h, q, dst);
    case 2 * 4 + 2: return upsampleEvenAs<2, 2>(src, covered, w, h, q, dst);
    case 3 * 4 + 1: return upsampleEvenAs<3, 1>(src, covered, w, h, q, dst);
    case 3 * 4 + 2: return upsampleEvenAs<3, 2>(src, covered, w, h, q, dst);
    case 4 * 4 + 1: return upsampleEvenAs<4, 1>(src, covered, w, h, q, dst);
    case 4 * 4 + 2: return upsampleEvenAs<4, 2>(src, covered, w, h, q, dst);
    default: std::abort();  // not a tile's layout (the loops held at most 4 components before too)
  }
}

size_t snapToPyramid(uint8_t* texels, const uint8_t* covered, uint32_t w, uint32_t h, TexelLayout layout,
                     const std::function<bool(const uint8_t*, const uint8_t*)>& close, std::vector<uint8_t>* payload) {
  const size_t tb = size_t(layout.texelBytes()), n = size_t(w) * h;
  const std::vector<Level> lv = levelsOf(w, h);
  // The payload is pyramidPayload's where its mask (texels of any byte not zero) is `covered`:
  // the level grids below are then the ones it makes.
  bool build = payload && n > 0 && lv.size() >= 2;
  if (payload) payload->clear();
  if (build) {
    const std::vector<uint8_t> cov = coverOf(texels, n, tb);
    for (size_t k = 0; k < n && build; ++k) build = cov[k] == (covered[k] != 0);
  }
  if (build) *payload = pyramidHead(texels, covered, w, h, lv, layout);  // the coarsest level is never snapped
  size_t snapped = 0;
  for (size_t l = lv.size() - 1; l-- > 0;) {
    const Level L = lv[l];
    LevelGrids g = levelOf(texels, covered, w, L, layout);
    for (uint32_t j = 0; j < L.h; ++j)
      for (uint32_t i = 0; i < L.w; ++i) {
        const size_t k = size_t(j) * L.w + i;
        uint8_t *a = &g.values[k * tb], *b = &g.rebuilt[k * tb];
        if ((!(i & 1) && !(j & 1)) || !g.cov[k] || sameTexel(a, b, tb)) continue;
        if (std::all_of(b, b + tb, [](uint8_t x) { return x == 0; }) || !close(a, b)) continue;
        copyTexel(texels + (size_t(j) * L.step * w + size_t(i) * L.step) * tb, b, tb);
        copyTexel(a, b, tb);  // the level as it now is (finer levels never move its texels)
        ++snapped;
      }
    if (build) encodeOdd(g, L, layout, *payload);
  }
  return snapped;
}

std::vector<uint8_t> encodeTile(const uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout, int level,
                                TileForm form, std::span<const uint8_t> pyramid) {
  // heights: LOCO-I alone was as small on the 2 M-point survey
  if (layout.comps == 1) return compress(residualPlanes(page, pageWidth, r, layout), level);
  // Normals and colours: the pyramid or LOCO-I, whichever codes smaller (both decode to the
  // same texels), judged by quickSize; snapped texels: the pyramid.
  std::vector<uint8_t> made;
  if (pyramid.empty()) made = pyramidPayload(page, pageWidth, r, layout);
  const std::span<const uint8_t> payload = pyramid.empty() ? std::span<const uint8_t>(made) : pyramid;
  if (!payload.empty() && form == TileForm::kPyramid) return pyramidBlob(payload, level);
  const std::vector<uint8_t> planes = residualPlanes(page, pageWidth, r, layout);
  if (!payload.empty() && quickSize(payload) < quickSize(planes)) return pyramidBlob(payload, level);
  return compress(planes, level);
}

Status decodeTile(std::span<const uint8_t> blob, uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout) {
  if (blob.size() >= sizeof kPyramidTag && std::equal(std::begin(kPyramidTag), std::end(kPyramidTag), blob.begin()))
    return decodePyramid(blob, page, pageWidth, r, layout);
  std::vector<uint8_t> planes;
  SA_RETURN_IF_ERROR(decompressExactly(blob, size_t(r.w) * r.h * layout.texelBytes(), planes));
  applyPlanes(planes.data(), page, pageWidth, r, layout);
  return Status::ok();
}

std::vector<uint8_t> encodeTilePlanes(std::span<const TilePlane> planes, int level) {
  std::vector<uint8_t> all;
  for (const TilePlane& p : planes) {
    const std::vector<uint8_t> r = residualPlanes(p.texels, p.stride, p.r, p.layout);
    all.insert(all.end(), r.begin(), r.end());
  }
  return compress(all, level);
}

Status decodeTilePlanes(std::span<const uint8_t> blob, std::span<const TilePlane> planes) {
  size_t want = 0;
  for (const TilePlane& p : planes) want += size_t(p.r.w) * p.r.h * p.layout.texelBytes();
  std::vector<uint8_t> all;
  SA_RETURN_IF_ERROR(decompressExactly(blob, want, all));
  size_t at = 0;
  for (const TilePlane& p : planes) {
    applyPlanes(all.data() + at, p.texels, p.stride, p.r, p.layout);
    at += size_t(p.r.w) * p.r.h * p.layout.texelBytes();
  }
  return Status::ok();
}

}  // namespace sa
