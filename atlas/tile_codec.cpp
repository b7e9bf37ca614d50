#include "atlas/tile_codec.h"

#include <zstd.h>

#include <algorithm>
#include <cstring>

namespace sa {
namespace {

constexpr int kZstdLevel = 1;

// LOCO-I's median edge detector: a left, b up, c up-left.
inline uint32_t predict(uint32_t a, uint32_t b, uint32_t c) {
  if (c >= std::max(a, b)) return std::min(a, b);
  if (c <= std::min(a, b)) return std::max(a, b);
  return a + b - c;
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

}  // namespace

std::vector<uint8_t> encodeTile(const uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout) {
  const size_t n = size_t(r.w) * r.h, tb = size_t(layout.texelBytes());
  const uint32_t mask = layout.bytes == 2 ? 0xffffu : 0xffu;
  std::vector<uint8_t> planes(n * tb);
  std::vector<uint32_t> rows(2 * size_t(r.w));
  for (int c = 0; c < layout.comps; ++c) {
    // Byte planes, component after component, low bytes first: the high bytes of small
    // residuals are runs of 0x00 and 0xff.
    uint8_t* lo = planes.data() + size_t(c) * layout.bytes * n;
    uint8_t* hi = lo + n;
    for (uint32_t j = 0; j < r.h; ++j) {
      uint32_t* cur = rows.data() + size_t(j & 1) * r.w;
      const uint32_t* prev = j ? rows.data() + size_t((j - 1) & 1) * r.w : nullptr;
      const uint8_t* row = page + ((size_t(r.y) + j) * pageWidth + r.x) * tb + size_t(c) * layout.bytes;
      for (uint32_t i = 0; i < r.w; ++i) cur[i] = readValue(row + i * tb, layout.bytes);
      for (uint32_t i = 0; i < r.w; ++i) {
        const size_t k = size_t(j) * r.w + i;
        const uint32_t res = (cur[i] - predictAt(cur, prev, i)) & mask;
        lo[k] = uint8_t(res);
        if (layout.bytes == 2) hi[k] = uint8_t(res >> 8);
      }
    }
  }
  std::vector<uint8_t> out(ZSTD_compressBound(planes.size()));
  const size_t z = ZSTD_compress(out.data(), out.size(), planes.data(), planes.size(), kZstdLevel);
  out.resize(ZSTD_isError(z) ? 0 : z);  // cannot fail: the bound holds
  return out;
}

Status decodeTile(std::span<const uint8_t> blob, uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout) {
  const size_t n = size_t(r.w) * r.h, tb = size_t(layout.texelBytes());
  const unsigned long long declared = ZSTD_getFrameContentSize(blob.data(), blob.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR || declared == ZSTD_CONTENTSIZE_UNKNOWN)
    return Status::badInput("not a zstd frame with its size");
  if (declared != n * tb)
    return Status::badInput("holds " + std::to_string(declared) + " bytes, the tile needs " + std::to_string(n * tb));
  std::vector<uint8_t> planes(n * tb);
  const size_t got = ZSTD_decompress(planes.data(), planes.size(), blob.data(), blob.size());
  if (ZSTD_isError(got)) return Status::badInput(std::string("damaged (") + ZSTD_getErrorName(got) + ")");
  if (got != planes.size()) return Status::badInput("decodes to fewer bytes than its frame says");
  const uint32_t mask = layout.bytes == 2 ? 0xffffu : 0xffu;
  std::vector<uint32_t> rows(2 * size_t(r.w));
  for (int c = 0; c < layout.comps; ++c) {
    const uint8_t* lo = planes.data() + size_t(c) * layout.bytes * n;
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
  return Status::ok();
}

}  // namespace sa
