#include "atlas/packing.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "common/error.h"

namespace sa {
namespace {

std::vector<uint32_t> shelfOrder(const std::vector<TileSize>& tiles) {
  std::vector<uint32_t> order(tiles.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
    if (tiles[a].h != tiles[b].h) return tiles[a].h > tiles[b].h;
    return tiles[a].w > tiles[b].w;
  });
  return order;
}

// Shelf packing in `order`; placements only when `out` is given. Returns the page count.
uint32_t shelves(const std::vector<TileSize>& tiles, const std::vector<uint32_t>& order, uint32_t pw, uint32_t ph,
                 std::vector<TilePlacement>* out) {
  uint32_t page = 0, shelfY = 0, shelfH = 0, cursorX = 0;
  for (uint32_t idx : order) {
    const uint32_t sw = tiles[idx].w + 2, sh = tiles[idx].h + 2;  // slot with gutters
    SA_CHECK(sw <= pw && sh <= ph);
    if (cursorX + sw > pw) {  // next shelf
      shelfY += shelfH;
      shelfH = 0;
      cursorX = 0;
    }
    if (shelfY + sh > ph) {  // next page
      ++page;
      shelfY = 0;
      shelfH = 0;
      cursorX = 0;
    }
    if (out) (*out)[idx] = {page, cursorX + 1, shelfY + 1};
    cursorX += sw;
    shelfH = std::max(shelfH, sh);
  }
  return page + 1;
}

constexpr uint32_t kMaxPages = 2048;

uint32_t pow2AtLeast(uint32_t v) {
  uint32_t p = 16;
  while (p < v) p *= 2;
  return p;
}

}  // namespace

PackingResult packTiles(const std::vector<TileSize>& tiles, uint32_t pageWidth, uint32_t pageHeight) {
  PackingResult r;
  r.pageWidth = pageWidth;
  r.pageHeight = pageHeight;
  r.placements.resize(tiles.size());
  if (tiles.empty()) return r;
  r.pageCount = shelves(tiles, shelfOrder(tiles), pageWidth, pageHeight, &r.placements);
  return r;
}

PackingResult packAtlas(const std::vector<TileSize>& tiles, uint32_t maxPageSize) {
  uint32_t maxW = 1, maxH = 1;
  for (const TileSize& t : tiles) {
    maxW = std::max(maxW, t.w);
    maxH = std::max(maxH, t.h);
  }
  const std::vector<uint32_t> order = shelfOrder(tiles);
  struct Candidate { uint32_t w, h, pages; double texels; };
  std::vector<Candidate> cands;
  for (uint32_t w = pow2AtLeast(maxW + 2); w <= maxPageSize; w *= 2)
    for (uint32_t h = pow2AtLeast(maxH + 2); h <= maxPageSize; h *= 2) {
      const uint32_t pages = tiles.empty() ? 1 : shelves(tiles, order, w, h, nullptr);
      cands.push_back({w, h, pages, double(pages) * w * h});
    }
  SA_CHECK(!cands.empty());
  // The fewest texels, give or take 3 %; among those the fewest pages (GL allows 2048 array
  // layers at least), then the squarer page.
  double least = 1e300;
  for (const Candidate& c : cands)
    if (c.pages <= kMaxPages) least = std::min(least, c.texels);
  const Candidate* best = nullptr;
  auto skew = [](const Candidate& c) { return std::max(c.w, c.h) / std::min(c.w, c.h); };
  for (const Candidate& c : cands) {
    const bool ok = least < 1e300 ? c.texels <= 1.03 * least && c.pages <= kMaxPages : true;
    if (!ok) continue;
    if (!best || c.pages < best->pages || (c.pages == best->pages && (c.texels < best->texels ||
                                                                       (c.texels == best->texels && skew(c) < skew(*best)))))
      best = &c;
  }
  PackingResult r;
  r.pageWidth = best->w;
  r.pageHeight = best->h;
  r.placements.resize(tiles.size());
  r.pageCount = tiles.empty() ? 1 : shelves(tiles, order, best->w, best->h, &r.placements);
  return r;
}

}  // namespace sa
