// Chunk halos: for each chunk of a pack that did not fit one chunk, the points of the other
// chunks that lie near its cube. Per-chunk work then sees across the chunk's faces as a pack of
// one chunk does: the surface fit of pass A (neighbours, normals, smoothing, the outlier test)
// and the cells' margins and normal field of pass B. Without them a chunk's face left one-sided
// fits and tiles that did not meet their neighbours': a seam of dark dashes along every chunk
// face (docs/BENCHMARKS.md, "Chunk halos").
//
// A source chunk writes, for each other chunk within `margin` of some of its points, one
// fragment file of those points' records (its own order); a target reads its fragments in the
// order of their source chunks. Which fragments exist depends only on the chunks' records, so a
// pack is the same on any number of threads or MPI ranks.
#pragma once
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "common/error.h"
#include "preprocess/chunker.h"

namespace sa {

// Which chunk's cube holds a quantized position (ChunkPoint::q): the chunks are octree nodes
// that do not overlap.
class ChunkLocator {
 public:
  explicit ChunkLocator(const std::vector<ChunkInfo>& chunks);
  // The chunk whose cube holds q, or -1.
  int64_t find(const uint32_t q[3]) const;

 private:
  std::unordered_map<uint64_t, uint32_t> byNode_;  // (level, ix, iy, iz) -> chunk
  std::vector<int> levels_;                        // the levels chunks are at, ascending
};

// Fragment files of one kind ("a": pass A's records as distributed; "b": pass B's, fitted) and,
// per target chunk, the source chunks that wrote one to it (ascending) with its record count.
struct HaloSet {
  std::string dir, kind;
  std::vector<std::vector<std::pair<uint32_t, uint64_t>>> from;
  std::string path(uint32_t source, uint32_t target) const;
  bool empty() const;
};

// Chunk `source`'s records pts: for every other chunk whose cube lies within `margin` (world
// units) of some of them, those records are written to a fragment file of h, and h.from gets
// (source, count) for that target. A chunk narrower than the margin may be missed where none of
// the probes around a point lands in it (chunks hold thousands of points and are hundreds of
// sample spacings wide; margins are a few).
Status writeHalo(HaloSet& h, const Quantizer& qz, const std::vector<ChunkInfo>& chunks, const ChunkLocator& where,
                 uint32_t source, std::span<const ChunkPoint> pts, double margin);

// Appends target's halo (its fragments, in the order of their sources) to out, at most `limit`
// records (the last fragment cut short there), each fragment passed to `adjust` (its source, its
// records) first when given, and removes the files.
Status takeHalo(const HaloSet& h, uint32_t target, ChunkRecords& out, size_t limit,
                const std::function<void(uint32_t source, std::span<ChunkPoint>)>& adjust = {});

// MPI: each rank writes the fragments of the chunks it owns; h.from as bytes for the others, and
// every rank's bytes merged into h.from (each list sorted by source).
std::vector<uint8_t> haloSources(const HaloSet& h);
void mergeHaloSources(HaloSet& h, const std::vector<std::vector<uint8_t>>& all);

}  // namespace sa
