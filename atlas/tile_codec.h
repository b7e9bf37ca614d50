// Lossless per-tile coding of the page sections (docs/FORMAT.md, "Compressed pages"): each
// cell's tile with its gutter is predicted texel by texel from its left, upper and upper-left
// neighbours (LOCO-I's median predictor, per component), the residuals split into byte planes
// and compressed by zstd. Tiles are coded alone, so any one decodes without the others.
#pragma once
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/error.h"

namespace sa {

// What a page texel holds: `comps` components of `bytes` bytes (1 or 2) each.
struct TexelLayout {
  int comps = 1;
  int bytes = 2;
  int texelBytes() const { return comps * bytes; }
};
inline constexpr TexelLayout kHeightTexels{1, 2};  // u16 height
inline constexpr TexelLayout kNormalTexels{2, 2};  // 2 x u16 octahedral normal
inline constexpr TexelLayout kColorTexels{4, 1};   // RGBA8

// A region of a page: x, y, w, h in texels, on a page `pageWidth` texels wide.
struct TileRegion {
  uint32_t x = 0, y = 0, w = 0, h = 0;
};

// Codes region r of `page` (row-major, pageWidth texels per row).
std::vector<uint8_t> encodeTile(const uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout);
// Decodes `blob` into region r of `page`; an error when the blob is not a tile of that size.
Status decodeTile(std::span<const uint8_t> blob, uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout);

}  // namespace sa
