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

// The prediction of texel (i, j) from the values v (w per row) already known.
inline uint32_t predictAt(const std::vector<uint32_t>& v, uint32_t w, uint32_t i, uint32_t j) {
  if (j == 0) return i ? v[i - 1] : 0;
  if (i == 0) return v[size_t(j - 1) * w];
  const size_t k = size_t(j) * w + i;
  return predict(v[k - 1], v[k - w], v[k - w - 1]);
}

uint32_t readValue(const uint8_t* p, int bytes) { return bytes == 2 ? uint32_t(p[0]) | uint32_t(p[1]) << 8 : p[0]; }

}  // namespace

std::vector<uint8_t> encodeTile(const uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout) {
  const size_t n = size_t(r.w) * r.h, tb = size_t(layout.texelBytes());
  const uint32_t mask = layout.bytes == 2 ? 0xffffu : 0xffu;
  std::vector<uint8_t> planes(n * tb);
  std::vector<uint32_t> v(n);
  for (int c = 0; c < layout.comps; ++c) {
    for (uint32_t j = 0; j < r.h; ++j) {
      const uint8_t* row = page + ((size_t(r.y) + j) * pageWidth + r.x) * tb + size_t(c) * layout.bytes;
      for (uint32_t i = 0; i < r.w; ++i) v[size_t(j) * r.w + i] = readValue(row + i * tb, layout.bytes);
    }
    // Byte planes, component after component, low bytes first: the high bytes of small
    // residuals are runs of 0x00 and 0xff.
    uint8_t* lo = planes.data() + size_t(c) * layout.bytes * n;
    uint8_t* hi = lo + n;
    for (uint32_t j = 0; j < r.h; ++j)
      for (uint32_t i = 0; i < r.w; ++i) {
        const size_t k = size_t(j) * r.w + i;
        const uint32_t res = (v[k] - predictAt(v, r.w, i, j)) & mask;
        lo[k] = uint8_t(res);
        if (layout.bytes == 2) hi[k] = uint8_t(res >> 8);
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
  std::vector<uint32_t> v(n);
  for (int c = 0; c < layout.comps; ++c) {
    const uint8_t* lo = planes.data() + size_t(c) * layout.bytes * n;
    const uint8_t* hi = lo + n;
    for (uint32_t j = 0; j < r.h; ++j) {
      uint8_t* row = page + ((size_t(r.y) + j) * pageWidth + r.x) * tb + size_t(c) * layout.bytes;
      for (uint32_t i = 0; i < r.w; ++i) {
        const size_t k = size_t(j) * r.w + i;
        const uint32_t res = layout.bytes == 2 ? uint32_t(lo[k]) | uint32_t(hi[k]) << 8 : lo[k];
        v[k] = (predictAt(v, r.w, i, j) + res) & mask;
        row[i * tb] = uint8_t(v[k]);
        if (layout.bytes == 2) row[i * tb + 1] = uint8_t(v[k] >> 8);
      }
    }
  }
  return Status::ok();
}

}  // namespace sa
