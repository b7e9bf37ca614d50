#include "preprocess/chunk_halo.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>

#include <tbb/parallel_for.h>

#include "common/fileio.h"
#include "common/serial.h"

namespace sa {
namespace {

constexpr int kMaxLevel = 15;  // a locator key: the level in 4 bits, node coordinates in 20 each
constexpr double kSpan = 4294967296.0;  // the root cube in quantized units

uint64_t nodeKey(int level, uint64_t ix, uint64_t iy, uint64_t iz) {
  return (uint64_t(level) << 60) | (ix << 40) | (iy << 20) | iz;
}

// A chunk's cube in quantized units: [lo, lo + size) on each axis.
void cubeOf(const ChunkInfo& c, double lo[3], double& size) {
  size = std::ldexp(1.0, 32 - c.level);
  lo[0] = c.ix * size, lo[1] = c.iy * size, lo[2] = c.iz * size;
}

}  // namespace

ChunkLocator::ChunkLocator(const std::vector<ChunkInfo>& chunks) {
  for (uint32_t c = 0; c < chunks.size(); ++c) {
    const ChunkInfo& ch = chunks[c];
    if (ch.level < 0 || ch.level > kMaxLevel) continue;  // not found: such a chunk gets no halo
    byNode_.emplace(nodeKey(ch.level, ch.ix, ch.iy, ch.iz), c);
    levels_.push_back(ch.level);
  }
  std::sort(levels_.begin(), levels_.end());
  levels_.erase(std::unique(levels_.begin(), levels_.end()), levels_.end());
}

int64_t ChunkLocator::find(const uint32_t q[3]) const {
  for (int l : levels_) {
    const int shift = 32 - l;
    auto at = [&](int a) { return l == 0 ? uint64_t(0) : uint64_t(q[a] >> shift); };
    const auto it = byNode_.find(nodeKey(l, at(0), at(1), at(2)));
    if (it != byNode_.end()) return it->second;
  }
  return -1;
}

std::string HaloSet::path(uint32_t source, uint32_t target) const {
  return joinPath(dir, "halo" + kind + "_" + std::to_string(source) + "_" + std::to_string(target) + ".bin");
}

bool HaloSet::empty() const {
  return std::all_of(from.begin(), from.end(), [](const auto& f) { return f.empty(); });
}

Status writeHalo(HaloSet& h, const Quantizer& qz, const std::vector<ChunkInfo>& chunks, const ChunkLocator& where,
                 uint32_t source, std::span<const ChunkPoint> pts, double margin) {
  const double m = margin / qz.cubeSize * kSpan;  // in quantized units
  if (!(m > 0) || chunks.size() < 2 || source >= chunks.size()) return Status::ok();
  h.from.resize(chunks.size());
  double lo[3], size;
  cubeOf(chunks[source], lo, size);
  // Per block of points (on every core), the (target, point) pairs in the points' order; the
  // blocks then joined in order, so the fragments do not depend on the scheduling.
  constexpr size_t kBlock = 1 << 14;
  std::vector<std::vector<std::pair<uint32_t, uint32_t>>> perBlock((pts.size() + kBlock - 1) / kBlock);
  tbb::parallel_for(size_t(0), perBlock.size(), [&](size_t b) {
    std::array<uint32_t, 26> found;
    const uint32_t end = uint32_t(std::min(pts.size(), (b + 1) * kBlock));
    for (uint32_t i = uint32_t(b * kBlock); i < end; ++i) {
      const double x[3] = {pts[i].q[0] + 0.5, pts[i].q[1] + 0.5, pts[i].q[2] + 0.5};  // as Quantizer decodes
      // Only a point within the margin of its own cube's faces can be near another cube.
      bool near = false;
      for (int a = 0; a < 3; ++a) near = near || x[a] - lo[a] <= m || lo[a] + size - x[a] <= m;
      if (!near) continue;
      // Probes at the corners, edge midpoints and face centres of the box [x - m, x + m]: a cube
      // at least m wide that meets the ball of radius m around x holds one of them (on each axis
      // its side, m long or more, holds x - m, x or x + m). All 26, also across the faces the
      // point is not near: a smaller neighbour may end within the margin along them.
      // Per axis the probe coordinates (x - m, x, x + m where inside the root cube) and whether
      // each leaves the point's own cube; a probe that leaves it on no axis finds its own chunk.
      uint32_t coord[3][3];
      bool leaves[3][3];
      int count[3];
      for (int a = 0; a < 3; ++a) {
        count[a] = 0;
        for (int d = -1; d <= 1; ++d) {
          const double p = x[a] + d * m;
          if (!(p >= 0 && p < kSpan)) continue;
          coord[a][count[a]] = uint32_t(p);
          leaves[a][count[a]++] = d != 0 && !(p >= lo[a] && p < lo[a] + size);
        }
      }
      size_t nf = 0;
      for (int k = 0; k < count[2]; ++k)
        for (int j = 0; j < count[1]; ++j)
          for (int i = 0; i < count[0]; ++i) {
            if (!(leaves[0][i] || leaves[1][j] || leaves[2][k])) continue;
            const uint32_t pq[3] = {coord[0][i], coord[1][j], coord[2][k]};
            const int64_t c = where.find(pq);
            if (c < 0 || uint32_t(c) == source || std::find(found.begin(), found.begin() + long(nf), uint32_t(c)) != found.begin() + long(nf))
              continue;
            double clo[3], csize, d2 = 0;  // squared distance from x to the cube
            cubeOf(chunks[size_t(c)], clo, csize);
            for (int a = 0; a < 3; ++a) {
              const double e = std::max({clo[a] - x[a], 0.0, x[a] - (clo[a] + csize)});
              d2 += e * e;
            }
            if (d2 <= m * m) found[nf++] = uint32_t(c);
          }
      for (size_t k = 0; k < nf; ++k) perBlock[b].emplace_back(found[k], i);
    }
  });
  std::map<uint32_t, std::vector<uint32_t>> byTarget;  // target -> indices into pts
  for (const auto& block : perBlock)
    for (const auto& [target, i] : block) byTarget[target].push_back(i);
  for (const auto& [target, idx] : byTarget) {
    std::vector<ChunkPoint> recs(idx.size());
    for (size_t k = 0; k < idx.size(); ++k) recs[k] = pts[idx[k]];
    SA_RETURN_IF_ERROR(saveChunk(h.path(source, target), recs));
    auto& list = h.from[target];
    list.insert(std::upper_bound(list.begin(), list.end(), std::make_pair(source, uint64_t(0))),
                {source, uint64_t(recs.size())});
  }
  return Status::ok();
}

Status takeHalo(const HaloSet& h, uint32_t target, ChunkRecords& out, size_t limit,
                const std::function<void(uint32_t source, std::span<ChunkPoint>)>& adjust) {
  if (target >= h.from.size()) return Status::ok();
  const size_t start = out.size();
  for (const auto& [source, count] : h.from[target]) {
    ChunkInfo frag;
    frag.path = h.path(source, target);
    frag.count = count;
    ChunkRecords recs;
    SA_RETURN_IF_ERROR(loadChunk(frag, recs));
    if (recs.size() != count) return Status::internal(frag.path + ": halo fragment shorter than recorded");
    std::remove(frag.path.c_str());
    recs.resize(std::min(recs.size(), limit - std::min(limit, out.size() - start)));
    if (adjust) adjust(source, std::span<ChunkPoint>(recs.data(), recs.size()));
    const size_t at = out.size();
    out.resize(at + recs.size());
    std::copy(recs.begin(), recs.end(), out.begin() + long(at));
  }
  return Status::ok();
}

std::vector<uint8_t> haloSources(const HaloSet& h) {
  ByteWriter w;
  for (uint32_t t = 0; t < h.from.size(); ++t)
    for (const auto& [source, count] : h.from[t]) w.put(t), w.put(source), w.put(count);
  return w.bytes();
}

void mergeHaloSources(HaloSet& h, const std::vector<std::vector<uint8_t>>& all) {
  for (auto& f : h.from) f.clear();
  for (const std::vector<uint8_t>& bytes : all) {
    ByteReader r(bytes);
    while (!r.done()) {
      uint32_t t = 0, source = 0;
      uint64_t count = 0;
      r.get(t), r.get(source), r.get(count);
      if (t >= h.from.size()) h.from.resize(t + 1);
      h.from[t].emplace_back(source, count);
    }
  }
  for (auto& f : h.from) std::sort(f.begin(), f.end());
}

}  // namespace sa
