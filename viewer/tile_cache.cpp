#include "viewer/tile_cache.h"

#include <algorithm>
#include <cmath>

#include <unistd.h>

namespace sa {
namespace {

uint32_t nextPow2(uint32_t v) {
  uint32_t p = 1;
  while (p < v) p <<= 1;
  return p;
}

}  // namespace

Status buildLevels(const PackReader& pack, uint32_t cell, uint32_t keepFrom, std::vector<TileImage>& out) {
  const CellRecord& c = pack.cells()[cell];
  const bool nn = pack.hasNormals(), cc = pack.hasColor();
  out.clear();
  // Where the pack stores a level no finer than the first one kept, the levels start there
  // (the finer ones sized, without texels); else from the decoded tile. A stored level that
  // fails to decode falls back to the tile.
  uint32_t stored = pack.storedLevelAtMost(cell, keepFrom);
  Status levelError = Status::ok();
  if (stored > 0) {
    for (uint32_t l = 0; l < stored; ++l) {
      uint32_t w, h;
      levelDims(c.tileW, c.tileH, l, w, h);
      out.push_back(TileImage{w, h, {}, {}, {}, {}});
    }
    out.emplace_back();
    levelError = pack.decodeStoredLevel(cell, stored, out.back());
    if (!levelError) {
      out.clear();
      stored = 0;
    }
  }
  Status s = Status::ok();
  if (out.empty()) {
    out.push_back(blankTile(c.tileW, c.tileH, nn, cc));
    TileImage& t = out.back();
    s = pack.decodeCellInto(cell, t.heights.data(), nn ? t.normals.data() : nullptr, cc ? t.rgba.data() : nullptr);
    if (!s) t = blankTile(c.tileW, c.tileH, nn, cc);  // a damaged tile: every level uncovered
  }
  while (out.back().w > 1 || out.back().h > 1) out.push_back(coarserLevel(out.back()));
  for (uint32_t k = stored; k < std::min<size_t>(keepFrom, out.size()); ++k)
    out[k] = TileImage{out[k].w, out[k].h, {}, {}, {}, {}};  // a new image: the texels' memory freed, not kept as capacity
  return s ? levelError : s;
}

uint64_t atlasBytes(const PackReader& pack) {
  const uint64_t texel = 2 + (pack.hasNormals() ? kNormalBytes : 0) + (pack.hasColor() ? 4 : 0);
  return pack.pageTexels() * pack.meta().pageCount * texel;
}

uint64_t physicalMemoryBytes() {
  const long pages = sysconf(_SC_PHYS_PAGES), size = sysconf(_SC_PAGE_SIZE);
  return pages > 0 && size > 0 ? uint64_t(pages) * uint64_t(size) : 0;
}

uint64_t defaultGpuBudget(uint64_t atlas, uint64_t ram, uint64_t gpu) {
  uint64_t room = UINT64_MAX;
  if (ram > 0) room = ram / 4;
  if (gpu > 0) room = std::min(room, gpu / 2);
  if (atlas <= room) return 0;
  return std::max<uint64_t>(room, uint64_t(16) << 20);
}

uint64_t levelBytes(const std::vector<TileImage>& levels) {
  uint64_t b = 0;
  for (const TileImage& t : levels) b += t.heights.size() * 2 + t.normals.size() + t.rgba.size() + t.cover.size() * 2;
  return b;
}

BlockAllocator::BlockAllocator(uint32_t size, uint32_t layers) : size_(size) {
  for (uint32_t l = 0; l < layers; ++l) {
    roots_.push_back(int(nodes_.size()));
    nodes_.push_back({l, 0, 0, size, size, -1, -1, false});
  }
}

// The smallest free leaf under n that holds w x h, or -1.
int BlockAllocator::find(int n, uint32_t w, uint32_t h) const {
  const Node& d = nodes_[n];
  if (d.w < w || d.h < h) return -1;
  if (d.child < 0) return d.used ? -1 : n;
  const int a = find(d.child, w, h), b = find(d.child + 1, w, h);
  if (a < 0 || b < 0) return a < 0 ? b : a;
  return uint64_t(nodes_[a].w) * nodes_[a].h <= uint64_t(nodes_[b].w) * nodes_[b].h ? a : b;
}

bool BlockAllocator::allocate(uint32_t w, uint32_t h, Block& out) {
  const uint32_t bw = nextPow2(std::max(w, 1u)), bh = nextPow2(std::max(h, 1u));
  int n = -1;
  for (int r : roots_) {
    const int f = find(r, bw, bh);
    if (f >= 0 && (n < 0 || uint64_t(nodes_[f].w) * nodes_[f].h < uint64_t(nodes_[n].w) * nodes_[n].h)) n = f;
  }
  if (n < 0) return false;
  for (;;) {  // split down to the block's size, the longer side first
    const Node d = nodes_[n];
    const bool splitW = d.w / 2 >= bw && (d.w >= d.h || d.h / 2 < bh);
    const bool splitH = !splitW && d.h / 2 >= bh;
    if (!splitW && !splitH) break;
    int c;
    if (!freeNodes_.empty()) {
      c = freeNodes_.back();
      freeNodes_.pop_back();
    } else {
      c = int(nodes_.size());
      nodes_.resize(nodes_.size() + 2);
    }
    const uint32_t hw = splitW ? d.w / 2 : d.w, hh = splitW ? d.h : d.h / 2;
    nodes_[c] = {d.layer, d.x, d.y, hw, hh, n, -1, false};
    nodes_[c + 1] = {d.layer, splitW ? d.x + hw : d.x, splitW ? d.y : d.y + hh, hw, hh, n, -1, false};
    nodes_[n].child = c;
    n = c;
  }
  Node& d = nodes_[n];
  d.used = true;
  used_ += uint64_t(d.w) * d.h;
  out = {d.layer, d.x, d.y, d.w, d.h, n};
  return true;
}

void BlockAllocator::release(const Block& b) {
  if (b.node < 0 || !nodes_[b.node].used) return;
  nodes_[b.node].used = false;
  used_ -= uint64_t(b.w) * b.h;
  for (int p = nodes_[b.node].parent; p >= 0; p = nodes_[p].parent) {  // merge free buddies upward
    const int c = nodes_[p].child;
    const Node &a = nodes_[c], &d = nodes_[c + 1];
    if (a.child >= 0 || d.child >= 0 || a.used || d.used) break;
    freeNodes_.push_back(c);
    nodes_[p].child = -1;
  }
}

TileResidency::TileResidency(std::span<const CellRecord> cells, uint32_t layerSize, uint32_t layers, uint64_t texelBytes)
    : cells_(cells),
      alloc_(layerSize, layers),
      texelBytes_(texelBytes),
      level_(cells.size(), -1),
      flags_(cells.size(), 0),
      block_(cells.size()),
      lastSeen_(cells.size(), 0),
      pos_(cells.size(), 0) {
  for (const CellRecord& c : cells) {
    const Eigen::Vector3d o(c.origin), u(c.u), v(c.v), w(c.w);
    center_.push_back(o + u * (c.box[0] + c.box[1]) / 2 + v * (c.box[2] + c.box[3]) / 2 + w * (c.box[4] + c.box[5]) / 2);
    radius_.push_back(0.5 * std::sqrt(std::pow(c.box[1] - c.box[0], 2) + std::pow(c.box[3] - c.box[2], 2) +
                                      std::pow(c.box[5] - c.box[4], 2)));
  }
}

void TileResidency::levelSize(const CellRecord& c, uint32_t level, uint32_t& w, uint32_t& h) {
  levelDims(c.tileW, c.tileH, level, w, h);
}

uint32_t TileResidency::levels(uint32_t cell) const { return levelCount(cells_[cell].tileW, cells_[cell].tileH); }

uint64_t TileResidency::blockTexels(uint32_t cell, uint32_t level) const {
  uint32_t w, h;
  levelSize(cells_[cell], level, w, h);
  return uint64_t(nextPow2(w + 2)) * nextPow2(h + 2);
}

void TileResidency::drop(uint32_t cell) {
  if (level_[cell] < 0) return;
  alloc_.release(block_[cell]);
  level_[cell] = -1;
  flags_[cell] = 0;
  const uint32_t p = pos_[cell], last = resident_.back();
  resident_[p] = last;
  pos_[last] = p;
  resident_.pop_back();
}

// A block of w x h, evicting the cells least recently seen (none seen this frame) until it fits.
bool TileResidency::makeRoom(uint32_t w, uint32_t h, BlockAllocator::Block& out, Frame& f) {
  while (!alloc_.allocate(w, h, out)) {
    int victim = -1;
    for (uint32_t c : resident_)
      if (lastSeen_[c] < frame_ && (victim < 0 || lastSeen_[c] < lastSeen_[uint32_t(victim)])) victim = int(c);
    if (victim < 0) return false;
    drop(uint32_t(victim));
    f.dropped.push_back(uint32_t(victim));
    ++f.evicted;
  }
  return true;
}

uint32_t TileResidency::levelForTexelPx(double px) {
  return px >= kMaxTexelPx ? 0 : uint32_t(std::floor(std::log2(kMaxTexelPx / std::max(px, 1e-9))));
}

TileResidency::Frame TileResidency::plan(std::span<const uint32_t> visible, const uint8_t* availFrom,
                                         const Eigen::Vector3d& eyeRel, double focalPx, uint64_t maxUploadBytes) {
  ++frame_;
  Frame out;
  std::vector<Want> wants;
  wants.reserve(visible.size());
  for (uint32_t cell : visible) {
    const CellRecord& c = cells_[cell];
    lastSeen_[cell] = frame_;
    const double dist = std::max((center_[cell] - eyeRel).norm() - radius_[cell], radius_[cell] * 1e-3 + 1e-30);
    const double texel = std::max((c.box[1] - c.box[0]) / c.tileW, (c.box[3] - c.box[2]) / c.tileH);
    const double px = texel * focalPx / dist;  // a level-0 texel's size on screen, in pixels
    wants.push_back({cell, std::min(levelForTexelPx(px), levels(cell) - 1), px});
  }
  std::vector<uint32_t> lv = fitLevels(wants, out.bias);
  std::vector<size_t> order(wants.size());
  for (size_t k = 0; k < order.size(); ++k) order[k] = k;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return wants[a].texelPx > wants[b].texelPx; });
  uint64_t bytes = 0;
  for (size_t k : order) {
    const Want& w = wants[k];
    if (lv[k] > w.level) ++out.coarsened;
    if (level_[w.cell] == int(lv[k])) continue;
    if (availFrom[w.cell] > lv[k]) {
      out.needs.push_back({w.cell, lv[k]});
      ++out.waiting;
      continue;
    }
    if (bytes >= maxUploadBytes) {
      ++out.waiting;
      continue;
    }
    bytes += place(w.cell, lv[k], out);
  }
  return out;
}

// Every visible cell `bias` levels coarser than it asks for, the fewest that fit the set in 70 %
// of the cache (the rest: the blocks' fragmentation); then, largest on screen first, a cell goes
// back one level finer while the set still fits, so the cache is filled where it shows most
// instead of a quarter used after the last coarsening step.
std::vector<uint32_t> TileResidency::fitLevels(const std::vector<Want>& wants, int& bias) const {
  const uint64_t room = alloc_.capacityTexels() * 7 / 10;
  auto at = [&](const Want& w, int b) { return std::min(w.level + uint32_t(b), levels(w.cell) - 1); };
  uint64_t texels = 0;
  for (bias = 0;; ++bias) {
    texels = 0;
    for (const Want& w : wants) texels += blockTexels(w.cell, at(w, bias));
    if (texels <= room || bias >= 24) break;
  }
  std::vector<uint32_t> lv(wants.size());
  for (size_t k = 0; k < wants.size(); ++k) lv[k] = at(wants[k], bias);
  if (bias == 0) return lv;
  std::vector<size_t> order(wants.size());
  for (size_t k = 0; k < order.size(); ++k) order[k] = k;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return wants[a].texelPx > wants[b].texelPx; });
  for (size_t k : order) {
    if (lv[k] <= wants[k].level) continue;
    const uint64_t now = blockTexels(wants[k].cell, lv[k]), finer = blockTexels(wants[k].cell, lv[k] - 1);
    if (texels - now + finer > room) continue;
    texels += finer - now;
    --lv[k];
  }
  return lv;
}

// Gives cell its block at level lv, evicting cells not seen this frame. Where the free space is
// too broken up for it, the cell takes the finest coarser level that finds a block (its own
// block given up first when that is what frees the room), so a view always settles. Returns the
// bytes uploaded (0 when the cell keeps what it has or finds no block: then it waits).
uint64_t TileResidency::place(uint32_t cell, uint32_t lv, Frame& out) {
  for (uint32_t l = lv; l < levels(cell); ++l) {
    if (level_[cell] == int(l)) return 0;  // what it holds is the best that fits
    uint32_t lw, lh;
    levelSize(cells_[cell], l, lw, lh);
    BlockAllocator::Block b;
    bool ok = makeRoom(lw + 2, lh + 2, b, out);
    if (!ok && level_[cell] >= 0 && int(l) > level_[cell]) {  // going coarser: its own block makes room
      drop(cell);
      ok = makeRoom(lw + 2, lh + 2, b, out);
    }
    if (!ok) continue;
    drop(cell);
    level_[cell] = int(l);
    flags_[cell] = 1;
    block_[cell] = b;
    pos_[cell] = uint32_t(resident_.size());
    resident_.push_back(cell);
    out.uploads.push_back({cell, l, b, lv});
    return uint64_t(lw + 2) * (lh + 2) * texelBytes_;
  }
  ++out.waiting;
  return 0;
}

}  // namespace sa
