#include "atlas/tile_levels.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include "atlas/pack_format.h"
#include "atlas/tile_codec.h"

namespace sa {
namespace {

// Of a sixteenth's four quarters, those that must be covered for it to be (coarserLevel).
constexpr int kCoverVotes = 2;

size_t at(const TileImage& t, int i, int j) { return size_t(j + 1) * (t.w + 2) + size_t(i + 1); }

// The gutter: the edge texels repeated (FORMAT.md).
void fillGutter(TileImage& t, bool normals, bool rgba) {
  auto copy = [&](int fi, int fj, int ti, int tj) {
    t.heights[at(t, ti, tj)] = t.heights[at(t, fi, fj)];
    if (!t.cover.empty()) t.cover[at(t, ti, tj)] = t.cover[at(t, fi, fj)];
    if (normals) std::copy_n(&t.normals[at(t, fi, fj) * kNormalBytes], kNormalBytes, &t.normals[at(t, ti, tj) * kNormalBytes]);
    if (rgba) std::copy_n(&t.rgba[at(t, fi, fj) * 4], 4, &t.rgba[at(t, ti, tj) * 4]);
  };
  const int W = int(t.w), H = int(t.h);
  for (int i = 0; i < W; ++i) {
    copy(i, 0, i, -1);
    copy(i, H - 1, i, H);
  }
  for (int j = -1; j <= H; ++j) {
    copy(0, std::clamp(j, 0, H - 1), -1, j);
    copy(W - 1, std::clamp(j, 0, H - 1), W, j);
  }
}

// The fine texels under coarse texel i of n across a tile of w (in fine texels, the coarse
// texel spans [i w / n, (i + 1) w / n)): their first index and each one's overlap (at most 3).
struct Span {
  uint32_t first = 0, count = 0;
  double weight[3] = {0, 0, 0};
};
Span span(uint32_t i, uint32_t n, uint32_t w) {
  const double a = double(i) * w / n, b = double(i + 1) * w / n;
  Span s;
  s.first = uint32_t(std::floor(a));
  for (uint32_t j = s.first; j < w && double(j) < b && s.count < 3; ++j)
    s.weight[s.count++] = std::min(b, double(j + 1)) - std::max(a, double(j));
  return s;
}

// Where the 8 sample points across each of n coarse texels (the centres of its sixteenths'
// quarters, at (k + 0.5) / (8 n) of the box for k = 0 .. 8 n - 1) fall on a level w texels across:
// the texel and the sixteenth of it, as coveredAt finds them. No sample lies on a boundary of a
// sixteenth ((2k + 1) w / (16 n) = m / 4 has no solution for w = 2n or 2n - 1), so rounding
// cannot move one.
struct SampleAxis {
  std::vector<uint32_t> texel;
  std::vector<uint8_t> sub;
};
SampleAxis sampleAxis(uint32_t n, uint32_t w) {
  SampleAxis s;
  s.texel.resize(size_t(8) * n);
  s.sub.resize(size_t(8) * n);
  for (uint32_t k = 0; k < 8 * n; ++k) {
    const double f = (k + 0.5) * w / (8.0 * n);
    const int i = std::clamp(int(f), 0, int(w) - 1);
    s.texel[k] = uint32_t(i);
    s.sub[k] = uint8_t(std::clamp(int((f - i) * 4), 0, 3));
  }
  return s;
}

// The votes of one row of sixteenths: 8 samples across each coarse texel in sample rows r0 and
// r1 (0 or 1 each) give quarter a of the texel's row of four sixteenths the sum of samples 2a and
// 2a + 1 in both rows; a sixteenth is covered at kCoverVotes. Eight samples at a time, in the bytes
// of one 64-bit word (sums of at most 4 stay inside their byte): bit a of the result for quarter a.
inline uint32_t rowVotes(const uint8_t* r0, const uint8_t* r1) {
  static_assert(kCoverVotes == 2, "the byte test below adds 126: a sum of 2 or more sets bit 7");
  static_assert(std::endian::native == std::endian::little, "sample k is byte k of the word");
  uint64_t x, y;
  std::memcpy(&x, r0, 8);
  std::memcpy(&y, r1, 8);
  x += y;
  x = (x + (x >> 8)) & 0x00ff00ff00ff00ffull;  // the quarters' sums, in bytes 0, 2, 4, 6
  x = (x + 0x007e007e007e007eull) & 0x0080008000800080ull;
  return uint32_t((x >> 7) & 1) | uint32_t((x >> 22) & 2) | uint32_t((x >> 37) & 4) | uint32_t((x >> 52) & 8);
}

// The masks of level t (t.w x t.h) from its finer level s: a sixteenth is covered where at least
// kCoverVotes of s's coverage at its quarters' centres are (coveredAt at the sample points,
// looked up row by row instead of point by point). At level 0 a sample row depends on its texel
// row alone, so sample rows on the same texel row share one.
void coverMasks(const TileImage& s, TileImage& t) {
  const SampleAxis su = sampleAxis(t.w, s.w), sv = sampleAxis(t.h, s.h);
  const size_t len = size_t(8) * t.w;
  std::vector<uint8_t> rows(8 * len);  // the 8 sample rows of one coarse row
  const uint8_t* row[8];
  for (uint32_t j = 0; j < t.h; ++j) {
    for (uint32_t r = 0; r < 8; ++r) {
      const uint32_t fj = sv.texel[8 * j + r], bit = 4u * sv.sub[8 * j + r];
      if (s.cover.empty() && r > 0 && fj == sv.texel[8 * j + r - 1]) {
        row[r] = row[r - 1];
        continue;
      }
      uint8_t* out = &rows[r * len];
      row[r] = out;
      const size_t base = at(s, 0, int(fj));  // the row's first texel
      const uint16_t* hr = &s.heights[base];
      if (s.cover.empty()) {  // level 0: a texel is covered whole or not at all
        for (size_t k = 0; k < len; ++k) out[k] = hr[su.texel[k]] != 0;
      } else {
        const uint16_t* cr = &s.cover[base];
        for (size_t k = 0; k < len; ++k)
          out[k] = uint8_t((hr[su.texel[k]] != 0) & ((cr[su.texel[k]] >> (bit + su.sub[k])) & 1u));
      }
    }
    for (uint32_t i = 0; i < t.w; ++i) {
      uint32_t m = 0;
      for (uint32_t b = 0; b < 4; ++b) m |= rowVotes(row[2 * b] + 8 * i, row[2 * b + 1] + 8 * i) << (4 * b);
      t.cover[at(t, int(i), int(j))] = uint16_t(m);
    }
  }
}

// A stored level's entry in a MIPZ blob: u32 level, u32 bytes of its frame.
struct LevelEntry {
  uint32_t level = 0, bytes = 0;
};
constexpr size_t kEntryBytes = sizeof(LevelEntry);
constexpr uint32_t kMaxStored = 16;

// The blob's entries and where each one's frame begins; false when the header does not fit the blob.
bool readEntries(std::span<const uint8_t> blob, std::vector<LevelEntry>& entries, std::vector<uint64_t>& starts,
                 bool* cover = nullptr) {
  uint32_t count = 0;
  if (blob.size() < 4) return false;
  std::memcpy(&count, blob.data(), 4);
  if (cover) *cover = (count & kStoredCover) != 0;
  count &= ~kStoredCover;
  if (count > kMaxStored || blob.size() < 4 + uint64_t(count) * kEntryBytes) return false;
  entries.resize(count);
  starts.resize(count);
  uint64_t off = 4 + uint64_t(count) * kEntryBytes;
  for (uint32_t k = 0; k < count; ++k) {
    std::memcpy(&entries[k], blob.data() + 4 + k * kEntryBytes, kEntryBytes);
    starts[k] = off;
    off += entries[k].bytes;
    if (off > blob.size() || (k > 0 && entries[k].level <= entries[k - 1].level) || entries[k].level > 31) return false;
  }
  return true;
}

// A level's channels as one frame holds them: the interior of each (heights, then normals and
// colours where the image has them), without the gutter.
std::vector<TilePlane> interiorPlanes(TileImage& t) {
  const TileRegion inside{1, 1, t.w, t.h};
  std::vector<TilePlane> planes{{reinterpret_cast<uint8_t*>(t.heights.data()), t.w + 2, inside, kHeightTexels}};
  if (!t.normals.empty()) planes.push_back({t.normals.data(), t.w + 2, inside, kNormalTexels});
  if (!t.rgba.empty()) planes.push_back({t.rgba.data(), t.w + 2, inside, kColorTexels});
  if (!t.cover.empty()) planes.push_back({reinterpret_cast<uint8_t*>(t.cover.data()), t.w + 2, inside, kHeightTexels});
  return planes;
}

}  // namespace

TileImage blankTile(uint32_t w, uint32_t h, bool normals, bool rgba) {
  TileImage t;
  t.w = w;
  t.h = h;
  const size_t n = size_t(w + 2) * (h + 2);
  t.heights.assign(n, 0);
  if (normals) t.normals.assign(n * kNormalBytes, 0);
  if (rgba) t.rgba.assign(n * 4, 0);
  return t;
}

bool coveredAt(const TileImage& t, double x, double y) {
  const double fx = x * t.w, fy = y * t.h;
  const int i = std::clamp(int(fx), 0, int(t.w) - 1), j = std::clamp(int(fy), 0, int(t.h) - 1);
  const size_t o = at(t, i, j);
  if (t.heights[o] == 0) return false;
  if (t.cover.empty()) return true;
  const int a = std::clamp(int((fx - i) * 4), 0, 3), b = std::clamp(int((fy - j) * 4), 0, 3);
  return (t.cover[o] >> (4 * b + a)) & 1u;
}

// A plain 2 x 2 mean would drift toward the far edge of an odd-sized tile by up to a fine texel
// at level 1 and about 3 at level 3 (the dragon's depth error p95 under a quarter budget 3.6
// texels; 1.5 with footprints).
TileImage coarserLevel(const TileImage& s) {
  const bool nn = !s.normals.empty(), cc = !s.rgba.empty();
  TileImage t = blankTile((s.w + 1) / 2, (s.h + 1) / 2, nn, cc);
  t.cover.assign(t.heights.size(), 0);
  coverMasks(s, t);
  std::vector<Span> su(t.w), sv(t.h);
  for (uint32_t i = 0; i < t.w; ++i) su[i] = span(i, t.w, s.w);
  for (uint32_t j = 0; j < t.h; ++j) sv[j] = span(j, t.h, s.h);
  for (uint32_t j = 0; j < t.h; ++j)
    for (uint32_t i = 0; i < t.w; ++i) {
      const size_t o = at(t, int(i), int(j));
      if (t.cover[o] == 0) continue;
      double h = 0, n[3] = {0, 0, 0}, c[4] = {0, 0, 0, 0}, covered = 0;
      const Span &a = su[i], &b = sv[j];
      for (uint32_t y = 0; y < b.count; ++y)
        for (uint32_t x = 0; x < a.count; ++x) {
          const double wt = a.weight[x] * b.weight[y];
          const size_t f = at(s, int(a.first + x), int(b.first + y));
          if (s.heights[f] == 0) continue;
          covered += wt;
          h += wt * s.heights[f];
          if (nn) {
            double d[3];
            decodeNormal(&s.normals[f * kNormalBytes], d);
            for (int q = 0; q < 3; ++q) n[q] += wt * d[q];
          }
          if (cc)
            for (int q = 0; q < 4; ++q) c[q] += wt * s.rgba[f * 4 + q];
        }
      if (covered <= 0) {  // not reached: a set bit lies on a covered texel under the footprint
        t.cover[o] = 0;
        continue;
      }
      t.heights[o] = uint16_t(std::clamp(lroundNonNegative(h / covered), 1L, 65535L));
      if (nn) {
        const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (len > 0) encodeNormal(n[0] / len, n[1] / len, n[2] / len, &t.normals[o * kNormalBytes]);
        else std::copy_n(&s.normals[at(s, int(a.first), int(b.first)) * kNormalBytes], kNormalBytes, &t.normals[o * kNormalBytes]);
      }
      if (cc)
        for (int q = 0; q < 4; ++q) t.rgba[o * 4 + q] = uint8_t(lroundNonNegative(c[q] / covered));
    }
  fillGutter(t, nn, cc);
  return t;
}

void levelDims(uint32_t w, uint32_t h, uint32_t level, uint32_t& lw, uint32_t& lh) {
  lw = w;
  lh = h;
  for (uint32_t k = 0; k < level && (lw > 1 || lh > 1); ++k) {
    lw = (lw + 1) / 2;
    lh = (lh + 1) / 2;
  }
}

uint32_t levelCount(uint32_t w, uint32_t h) {
  uint32_t n = 1;
  while (w > 1 || h > 1) {
    w = (w + 1) / 2;
    h = (h + 1) / 2;
    ++n;
  }
  return n;
}

std::vector<uint8_t> encodeStoredLevels(TileImage t, int zstdLevel) {
  const uint32_t levels = levelCount(t.w, t.h);
  std::vector<LevelEntry> entries;
  std::vector<std::vector<uint8_t>> frames;
  uint32_t lv = 0;
  for (uint32_t want : kStoredLevels) {
    if (want >= levels) break;
    for (; lv < want; ++lv) t = coarserLevel(t);
    frames.push_back(encodeTilePlanes(interiorPlanes(t), zstdLevel));
    entries.push_back({want, uint32_t(frames.back().size())});
  }
  const uint32_t count = uint32_t(entries.size()) | kStoredCover;
  std::vector<uint8_t> out(4 + entries.size() * kEntryBytes);
  std::memcpy(out.data(), &count, 4);
  for (size_t k = 0; k < entries.size(); ++k) std::memcpy(out.data() + 4 + k * kEntryBytes, &entries[k], kEntryBytes);
  for (const std::vector<uint8_t>& f : frames) out.insert(out.end(), f.begin(), f.end());
  return out;
}

uint32_t storedLevelAtMost(std::span<const uint8_t> blob, uint32_t atMost) {
  std::vector<LevelEntry> entries;
  std::vector<uint64_t> starts;
  if (!readEntries(blob, entries, starts)) return 0;
  uint32_t best = 0;
  for (const LevelEntry& e : entries)
    if (e.level <= atMost) best = e.level;
  return best;
}

Status decodeStoredLevel(std::span<const uint8_t> blob, uint32_t tileW, uint32_t tileH, uint32_t level, bool normals,
                         bool rgba, TileImage& out) {
  std::vector<LevelEntry> entries;
  std::vector<uint64_t> starts;
  bool cover = false;
  if (!readEntries(blob, entries, starts, &cover)) return Status::badInput("stored levels: a corrupt header");
  size_t k = 0;
  while (k < entries.size() && entries[k].level != level) ++k;
  if (k == entries.size() || level >= levelCount(tileW, tileH))
    return Status::badInput("stored levels: no level " + std::to_string(level));
  uint32_t w, h;
  levelDims(tileW, tileH, level, w, h);
  out = blankTile(w, h, normals, rgba);
  if (cover) out.cover.assign(out.heights.size(), 0);
  const Status s = decodeTilePlanes(blob.subspan(starts[k], entries[k].bytes), interiorPlanes(out));
  if (!s) return Status::badInput("stored level " + std::to_string(level) + ": " + s.message());
  fillGutter(out, normals, rgba);
  return Status::ok();
}

}  // namespace sa
