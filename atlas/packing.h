// Packs rectangular tiles into square pages (array-texture layers) with a one-texel gutter
// around each tile. Shelf packing of tiles sorted by height: simple, deterministic, and
// close to optimal here because tile sizes come in few distinct values.
#pragma once
#include <cstdint>
#include <vector>

namespace sa {

struct TileSize { uint32_t w = 1, h = 1; };
struct TilePlacement { uint32_t page = 0, x = 0, y = 0; };  // x, y: first interior texel

struct PackingResult {
  uint32_t pageSize = 0;
  uint32_t pageCount = 0;
  std::vector<TilePlacement> placements;  // same order as the input tiles
};

// Every tile must satisfy w + 2 <= pageSize and h + 2 <= pageSize.
PackingResult packTiles(const std::vector<TileSize>& tiles, uint32_t pageSize);

// A page size (power of two, 64..maxPageSize) suited to the total texel count.
uint32_t choosePageSize(uint64_t totalTexelsWithGutters, uint32_t largestTileSide, uint32_t maxPageSize);

}  // namespace sa
