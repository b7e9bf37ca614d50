// Lossless per-tile coding of the page sections (docs/FORMAT.md, "Compressed pages"): each
// cell's tile with its gutter is predicted texel by texel from its left, upper and upper-left
// neighbours (LOCO-I's median predictor, per component), the residuals split into byte planes
// and compressed by zstd. Tiles are coded alone, so any one decodes without the others. Normal
// and colour tiles may instead be coded as a pyramid, when smaller: the texels at every 2^L-th
// column and row so, and each finer level's other texels as their difference to the rebuild
// from the level above (upsampleEven), which is zero wherever the writer snapped a texel to that
// rebuild (snapToPyramid).
#pragma once
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "common/error.h"

namespace sa {

// What a page texel holds: `comps` components of `bytes` bytes (1 or 2) each.
// Rebuilt texels are rounded to multiples of `quantum` (the normals' kNormalStep).
struct TexelLayout {
  int comps = 1;
  int bytes = 2;
  uint32_t quantum = 1;
  int texelBytes() const { return comps * bytes; }
};
inline constexpr TexelLayout kHeightTexels{1, 2, 1};   // u16 height
inline constexpr TexelLayout kNormalTexels{2, 2, 64};  // 2 x u16 octahedral normal, multiples of 64
inline constexpr TexelLayout kColorTexels{4, 1, 1};    // RGBA8

// The levels above the tile a pyramid blob of a w x h tile (without gutter) has: halving while
// both sides are 4 texels or more, at most kMaxPyramidLevels times.
inline constexpr int kMaxPyramidLevels = 4;
int pyramidLevels(uint32_t w, uint32_t h);

// Rebuilds a w x h tile (row-major, tight) from its even texels (even column and even row of
// `src`; the others are not read): those are copied, every other texel is zero where `covered`
// (one byte a texel) is 0, else each component the mean of its covered even neighbours (the
// two beside it along an odd axis, the four diagonal ones at odd/odd; one at an odd last
// row or column), rounded to a multiple of the quantum; zero when none is covered.
void upsampleEven(const uint8_t* src, const uint8_t* covered, uint32_t w, uint32_t h, TexelLayout layout, uint8_t* dst);

// A region of a page: x, y, w, h in texels, on a page `pageWidth` texels wide.
struct TileRegion {
  uint32_t x = 0, y = 0, w = 0, h = 0;
};

// Sets texels of a w x h tile (row-major, tight, no gutter) to their rebuild from the pyramid
// level above, coarsest level first, wherever `close(before, after)` accepts the change and the
// texel is covered with a covered neighbour on that level: the pyramid blob then holds a zero
// for it. The even/even texels of the coarsest level keep their values. Returns the texels
// changed. Where `payload` is given it is set to the snapped tile's pyramid payload, the bytes
// encodeTile would make for the tile from its texels (pass it there): the levels are built here
// anyway. It is left empty where those would not be the same bytes (a covered texel whose bytes
// are all zero, or an uncovered one that has some) or the tile has no pyramid.
size_t snapToPyramid(uint8_t* texels, const uint8_t* covered, uint32_t w, uint32_t h, TexelLayout layout,
                     const std::function<bool(const uint8_t*, const uint8_t*)>& close,
                     std::vector<uint8_t>* payload = nullptr);

// zstd's level for the coded tiles, unless the writer is told otherwise (pack --zstd-level): on
// the 2 M-point survey 6 gave 5.4 % fewer bytes than 1 for 8.5 % more packing time; decoding
// costs the same at any level. Levels up to 12 look only for matches of 6 bytes or more
// (tile_codec.cpp, kTileMinMatch).
inline constexpr int kDefaultTileLevel = 6;
inline constexpr int kMaxTileLevel = 19;

// The forms a normal or colour tile may be coded in (heights are always LOCO-I planes):
// kSmaller sizes the pyramid and the LOCO-I planes and codes whichever is smaller; kPyramid
// codes the pyramid without sizing the planes, for texels already snapped to it (snapToPyramid):
// there LOCO-I won 0.01-0.16 % of the normal bytes of the real scans and the survey, and sizing
// it was about a twentieth of the heightmaps phase. A tile too small for a pyramid, or whose
// gutter does not repeat it, is LOCO-I either way.
enum class TileForm { kSmaller, kPyramid };

// Codes region r of `page` (row-major, pageWidth texels per row) at zstd level `level`.
// `pyramid`: the region's pyramid payload when snapToPyramid made it for the same texels (the
// region then holds the tile and a gutter repeating it); empty: made here.
std::vector<uint8_t> encodeTile(const uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout,
                                int level = kDefaultTileLevel, TileForm form = TileForm::kSmaller,
                                std::span<const uint8_t> pyramid = {});
// Decodes `blob` into region r of `page`; an error when the blob is not a tile of that size.
Status decodeTile(std::span<const uint8_t> blob, uint8_t* page, uint32_t pageWidth, TileRegion r, TexelLayout layout);

// Several small regions coded as one zstd frame, their residual planes one after another: what
// a cell's stored levels share instead of a frame each (a frame costs about 10 bytes, a 6 x 6
// height tile about 50).
struct TilePlane {
  uint8_t* texels;       // read by encodeTilePlanes, written by decodeTilePlanes
  uint32_t stride = 0;   // texels a row
  TileRegion r;          // the region coded
  TexelLayout layout;
};
std::vector<uint8_t> encodeTilePlanes(std::span<const TilePlane> planes, int level = kDefaultTileLevel);
// An error when the blob is not one frame of exactly those planes.
Status decodeTilePlanes(std::span<const uint8_t> blob, std::span<const TilePlane> planes);

}  // namespace sa
