// Packs rectangular tiles into pages (array-texture layers) with a one-texel gutter around
// each tile. Shelf packing of tiles sorted by height: simple, deterministic, and close to
// optimal here because tile sizes come in few distinct values. Pages need not be square: the
// page shape is chosen for the tiles, so a long thin scan is not padded to a square.
#pragma once
#include <cstdint>
#include <vector>

namespace sa {

struct TileSize { uint32_t w = 1, h = 1; };
struct TilePlacement { uint32_t page = 0, x = 0, y = 0; };  // x, y: first interior texel

struct PackingResult {
  uint32_t pageWidth = 0, pageHeight = 0;
  uint32_t pageCount = 0;
  std::vector<TilePlacement> placements;  // same order as the input tiles
};

// Every tile must satisfy w + 2 <= pageWidth and h + 2 <= pageHeight.
PackingResult packTiles(const std::vector<TileSize>& tiles, uint32_t pageWidth, uint32_t pageHeight);

// Packs into the page shape (each side a power of two, 16 .. maxPageSize) that allocates the
// fewest texels over whole pages; on a tie, the fewer pages, then the squarer page. Every tile
// must satisfy w + 2 <= maxPageSize and h + 2 <= maxPageSize.
PackingResult packAtlas(const std::vector<TileSize>& tiles, uint32_t maxPageSize);

}  // namespace sa
