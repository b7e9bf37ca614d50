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
  // Levels above 0: per texel the coverage of its 4 x 4 sixteenths, bit 4 b + a for column a
  // and row b (u and v increasing), 0 where the texel is uncovered. Empty: a covered texel is
  // covered throughout (level 0, and the stored levels of packs before pipeline revision 15).
  std::vector<uint16_t> cover;
};

// An uncovered w x h tile with its gutter, with or without normal and colour texels.
TileImage blankTile(uint32_t w, uint32_t h, bool normals, bool rgba);
// The next level of t: ceil(w / 2) x ceil(h / 2) texels over the same box (the shader spreads a
// level's texels evenly over the cell's box), each the area average of the texels under its
// footprint, which is 2 w / (w + 1) texels wide where w is odd. Its coverage is a 4 x 4 mask
// (cover): a sixteenth is covered where at least 2 of t's coverage (coveredAt) at the centres
// of its quarters are, and the texel where any sixteenth is; height and colour the covered
// texels' weighted mean, the normal their normalized weighted mean. So a far view's coverage
// edges stay within about a sixteenth of a coarse texel of level 0's, while holes and specks
// under about a quarter of it close (without masks a texel's coverage was a share of its
// footprint, and an edge moved by up to half a texel: a budget render of the 2 M-point survey
// differed from the full one in 0.8 % of its pixels; docs/BENCHMARKS.md, "Sub-texel coverage
// of coarse levels").
TileImage coarserLevel(const TileImage& t);
// Whether t covers the point (x, y) of its box, x and y in [0, 1): the texel there is covered and,
// where t has a mask, so is the mask's sixteenth there (the shader's sampleHeight decides so).
bool coveredAt(const TileImage& t, double x, double y);
// A mask with every bit set: a texel covered throughout.
inline constexpr uint16_t kFullCover = 0xffff;

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
// the same texels as building them itself), each level's channels coded by the tile codec as one
// frame at zstd `zstdLevel`. Layout (FORMAT.md, "Stored levels"): u32 count | kStoredCover; per
// stored level u32 level and u32 bytes of its frame; then the frames: heights, normals and
// colours where the pack has them, and the coverage masks.
std::vector<uint8_t> encodeStoredLevels(TileImage level0, int zstdLevel);
// The flag in a MIPZ blob's count word that says its frames hold the coverage masks (packs from
// pipeline revision 15 on; older blobs decode without masks).
inline constexpr uint32_t kStoredCover = 1u << 16;
// The finest level a blob stores that is no finer than `atMost` (0: none).
uint32_t storedLevelAtMost(std::span<const uint8_t> blob, uint32_t atMost);
// Decodes stored `level` of a tileW x tileH tile from its blob into `out` (sized here); an error
// names what is wrong with the blob. normals, rgba: whether the pack has them.
Status decodeStoredLevel(std::span<const uint8_t> blob, uint32_t tileW, uint32_t tileH, uint32_t level, bool normals,
                         bool rgba, TileImage& out);

}  // namespace sa
