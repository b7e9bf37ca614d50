// A cell's tile at coarser levels (each half the texels along each side, covering the same box)
// and the few of them a pack stores (MIPZ, FORMAT.md "Stored levels"), so that a far view needs
// only a small level decoded instead of the whole tile. No GL here: the viewer's tile cache
// builds and uploads the levels; the pack writer stores them.
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "common/error.h"

namespace sa {

// One level of a cell's tile with its one-texel gutter (the edge repeated), row-major,
// (w + 2) x (h + 2) texels. A height of 0 is an uncovered texel.
struct TileImage {
  uint32_t w = 0, h = 0;  // interior texels
  std::vector<uint16_t> heights;
  std::vector<uint8_t> normals;  // kNormalBytes a texel, empty when the pack has none
  std::vector<uint8_t> rgba;     // empty when the pack has no colour
};

// An uncovered w x h tile with its gutter, with or without normal and colour texels.
TileImage blankTile(uint32_t w, uint32_t h, bool normals, bool rgba);
// The next level of t: ceil(w / 2) x ceil(h / 2) texels over the same box (the shader spreads a
// level's texels evenly over the cell's box), each the area average of the texels under its
// footprint, which is 2 w / (w + 1) texels wide where w is odd. Covered where at least `share`
// of the footprint is (coverShare); height and colour the covered texels' weighted mean, the
// normal their normalized weighted mean.
TileImage coarserLevel(const TileImage& t, double share);

// The share of a coarse texel's footprint that must be covered for the texel to be covered.
// Rasterized meshes: half, so a coverage edge stays where it was on average (a triangle's edge
// is exact: the dragon's mesh loses about as many pixels as it gains). Point packs: 0.4. Their
// cells overlap nowhere at creases (a margin texel that turns away is dropped), so a roof's and
// its wall's coverage only meet there, and a level that pulls both edges back by up to half its
// texel opens a crack into the building's hollow; their coverage edges are ragged unions of
// splats besides. The 2 M-point survey's far views under a budget lost 2.5 times the pixels they
// gained at half (docs/BENCHMARKS.md, "Coarse coverage of point packs").
inline constexpr double kMeshCoverShare = 0.5, kPointCoverShare = 0.4;
inline double coverShare(bool fromTriangles) { return fromTriangles ? kMeshCoverShare : kPointCoverShare; }
// The interior size of a w x h tile at a level (ceil-halved `level` times).
void levelDims(uint32_t w, uint32_t h, uint32_t level, uint32_t& lw, uint32_t& lh);
// The levels a w x h tile has: 1 + the halvings down to one texel.
uint32_t levelCount(uint32_t w, uint32_t h);

// The levels a pack stores beside each tile (MIPZ): level 2 serves views where a texel covers
// a quarter pixel or less, level 4 far overviews; each is 1/16 of the texels of the level it
// replaces. A level a tile does not have (a tile of under 2^L texels on its longer side) is
// left out.
inline constexpr uint32_t kStoredLevels[] = {4};

// A cell's MIPZ blob: its stored levels, built by coarserLevel from level 0 (so a reader gets
// the same texels as building them itself), each channel coded by the tile codec at zstd
// `zstdLevel`. Layout: u32 count; per stored level u32 level and u32 bytes of its heights,
// normals and colours (0: the channel is absent); then the coded channels in that order.
// `share`: coarserLevel's, the reader's for the pack (coverShare).
std::vector<uint8_t> encodeStoredLevels(TileImage level0, int zstdLevel, double share);
// The finest level a blob stores that is no finer than `atMost` (0: none).
uint32_t storedLevelAtMost(std::span<const uint8_t> blob, uint32_t atMost);
// Decodes stored `level` of a tileW x tileH tile from its blob into `out` (sized here); an error
// names what is wrong with the blob. normals, rgba: whether the pack has them.
Status decodeStoredLevel(std::span<const uint8_t> blob, uint32_t tileW, uint32_t tileH, uint32_t level, bool normals,
                         bool rgba, TileImage& out);

}  // namespace sa
