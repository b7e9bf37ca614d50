#include "atlas/packing.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "common/error.h"

namespace sa {

PackingResult packTiles(const std::vector<TileSize>& tiles, uint32_t pageSize) {
  PackingResult r;
  r.pageSize = pageSize;
  r.placements.resize(tiles.size());
  if (tiles.empty()) return r;
  std::vector<uint32_t> order(tiles.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
    if (tiles[a].h != tiles[b].h) return tiles[a].h > tiles[b].h;
    return tiles[a].w > tiles[b].w;
  });
  uint32_t page = 0, shelfY = 0, shelfH = 0, cursorX = 0;
  for (uint32_t idx : order) {
    const uint32_t sw = tiles[idx].w + 2, sh = tiles[idx].h + 2;  // slot with gutters
    SA_CHECK(sw <= pageSize && sh <= pageSize);
    if (cursorX + sw > pageSize) {  // next shelf
      shelfY += shelfH;
      shelfH = 0;
      cursorX = 0;
    }
    if (shelfY + sh > pageSize) {  // next page
      ++page;
      shelfY = 0;
      shelfH = 0;
      cursorX = 0;
    }
    r.placements[idx] = {page, cursorX + 1, shelfY + 1};
    cursorX += sw;
    shelfH = std::max(shelfH, sh);
  }
  r.pageCount = page + 1;
  return r;
}

uint32_t choosePageSize(uint64_t totalTexels, uint32_t largestTileSide, uint32_t maxPageSize) {
  // The power of two that allocates the fewest texels over whole pages (shelf packing wastes
  // a few percent, hence the margin); on a tie the larger page (fewer layers).
  uint32_t best = maxPageSize;
  double bestBytes = 1e300;
  for (uint32_t size = 64; size <= maxPageSize; size *= 2) {
    if (size < largestTileSide + 2) continue;
    const double pages = std::ceil(static_cast<double>(totalTexels) * 1.08 / (double(size) * size));
    const double alloc = std::max(1.0, pages) * double(size) * size;
    if (alloc <= bestBytes) {
      bestBytes = alloc;
      best = size;
    }
  }
  return best;
}

}  // namespace sa
