// A GPU budget for a pack's tiles (--gpu-budget): which level of each cell's tile is resident in
// a fixed cache of texture layers, and where. Coarser levels (each half the texels along each
// side, covering the same box, so the shaders draw them unchanged) serve cells whose texels
// would be under kMaxTexelPx pixels; when the visible set still does not fit, every visible
// cell goes one level coarser until it does. Blocks of the cache are handed out by a buddy
// allocator; cells not visible this frame are evicted least recently seen first. No GL here:
// the renderer uploads what plan() returns.
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "atlas/pack_file.h"
#include "atlas/tile_levels.h"

namespace sa {

// The largest a resident texel may be on screen, in pixels, before a finer level is asked for:
// its diagonal under a pixel. At a whole pixel a coarse level's sub-pixel edges and pinholes
// land in other pixels than level 0's (docs/BENCHMARKS.md, "The level a view asks for").
inline constexpr double kMaxTexelPx = 0.70710678118654752;

// Levels 0, 1, 2, ... of cell i's tile, down to one texel on the longer side, level 0 decoded
// from the pack (PackReader::decodeCellInto: any PageLoad but kNone) and each coarser one by
// coarserLevel; where the pack stores a level between 1 and keepFrom (MIPZ), the finest such
// is decoded instead of the tile (the same texels: the writer built it by coarserLevel too).
// Levels under keepFrom are left empty (their size set, no texels): what is not needed is not
// kept. A tile that fails to decode gets its levels all uncovered (the cell never draws) and
// the error is returned; a stored level that fails is built from the tile, and its error returned.
Status buildLevels(const PackReader& pack, uint32_t i, uint32_t keepFrom, std::vector<TileImage>& out);
// The bytes the pack's pages take on the GPU when uploaded whole.
uint64_t atlasBytes(const PackReader& pack);
// This machine's physical memory (0 where unknown).
uint64_t physicalMemoryBytes();
// The GPU budget when --gpu-budget is not given: none (0) while the whole atlas fits in a
// quarter of RAM (its decoded pages and the driver's copy, which on a software or integrated
// GPU is RAM too) and, where the GPU says (gpuBytes > 0), in half of its memory; else the
// smaller of those, at least 16 MiB.
uint64_t defaultGpuBudget(uint64_t atlasBytes, uint64_t ramBytes, uint64_t gpuBytes);
// --gpu-budget resolved for one pack: bytes (0: every tile resident); automatic: not given, so
// the default, which the GPU's own memory may still lower once a GL context exists.
struct GpuBudget {
  uint64_t bytes = 0;
  bool automatic = false;
  uint64_t atlas = 0, ram = 0;
};
// The bytes of texels a cell's levels hold.
uint64_t levelBytes(const std::vector<TileImage>& levels);

// A buddy allocator of power-of-two rectangles over `layers` square layers of `size` texels.
class BlockAllocator {
 public:
  struct Block {
    uint32_t layer = 0, x = 0, y = 0, w = 0, h = 0;
    int node = -1;
  };
  BlockAllocator(uint32_t size, uint32_t layers);
  // A block of at least w x h texels (rounded up to powers of two); false when none is free.
  bool allocate(uint32_t w, uint32_t h, Block& out);
  void release(const Block& b);
  uint64_t usedTexels() const { return used_; }
  uint64_t capacityTexels() const { return uint64_t(size_) * size_ * roots_.size(); }

 private:
  struct Node {
    uint32_t layer, x, y, w, h;
    int parent, child;  // child: the first of two (-1: a leaf)
    bool used;
  };
  int find(int n, uint32_t w, uint32_t h) const;
  uint32_t size_;
  std::vector<int> roots_;
  std::vector<Node> nodes_;
  std::vector<int> freeNodes_;  // recycled node slots (pairs)
  uint64_t used_ = 0;
};

// Per cell: the resident level and its block; per frame: what to upload.
class TileResidency {
 public:
  // texelBytes: bytes of one texel over every page channel.
  TileResidency(std::span<const CellRecord> cells, uint32_t layerSize, uint32_t layers, uint64_t texelBytes);
  struct Upload {
    uint32_t cell = 0, level = 0;
    BlockAllocator::Block block;
    uint32_t wanted = 0;  // the level planned; finer than `level` where no block was free for it
  };
  struct Need {
    uint32_t cell = 0, level = 0;
  };
  struct Frame {
    std::vector<Upload> uploads;   // in priority order, blocks allocated (old ones released)
    std::vector<Need> needs;       // visible cells whose wanted level is not in memory, in priority order
    std::vector<uint32_t> dropped; // cells that lost their block to make room
    uint32_t evicted = 0;          // cells that lost their block to make room
    uint32_t coarsened = 0;        // visible cells wanted coarser than their texels ask, to fit the budget
    uint32_t waiting = 0;          // visible cells not at their wanted level after this frame's uploads
    int bias = 0;                  // levels every visible cell went coarser to fit
  };
  // visible: the cells the frame draws or lacks; availFrom[cell]: the finest of its levels in
  // memory (every coarser one is too), kNoLevel when none.
  // eyeRel: the camera relative to the pack origin; focalPx: pixels per unit of depth.
  static constexpr uint8_t kNoLevel = 255;
  Frame plan(std::span<const uint32_t> visible, const uint8_t* availFrom, const Eigen::Vector3d& eyeRel, double focalPx,
             uint64_t maxUploadBytes);
  // The coarsest level whose texels stay under kMaxTexelPx pixels on screen, where a level-0
  // texel is px pixels (level 0 where even those are larger).
  static uint32_t levelForTexelPx(double px);
  int level(uint32_t cell) const { return level_[cell]; }   // -1: not resident
  uint32_t levels(uint32_t cell) const;                     // levels the cell has (1 + its mips)
  uint64_t residentBytes() const { return alloc_.usedTexels() * texelBytes_; }
  uint64_t capacityBytes() const { return alloc_.capacityTexels() * texelBytes_; }
  // The interior size of cell c's tile at a level.
  static void levelSize(const CellRecord& c, uint32_t level, uint32_t& w, uint32_t& h);
  const uint8_t* residentFlags() const { return flags_.data(); }

 private:
  struct Want {
    uint32_t cell, level;  // the level its texels on screen ask for
    double texelPx;        // a level-0 texel's size on screen, in pixels
  };
  std::vector<uint32_t> fitLevels(const std::vector<Want>& wants, int& bias) const;
  uint64_t place(uint32_t cell, uint32_t lv, Frame& out);
  uint64_t blockTexels(uint32_t cell, uint32_t level) const;
  bool makeRoom(uint32_t w, uint32_t h, BlockAllocator::Block& out, Frame& f);
  void drop(uint32_t cell);
  std::span<const CellRecord> cells_;
  std::vector<Eigen::Vector3d> center_;
  std::vector<double> radius_;
  BlockAllocator alloc_;
  uint64_t texelBytes_;
  std::vector<int> level_;
  std::vector<uint8_t> flags_;  // level_ >= 0, for the culler
  std::vector<BlockAllocator::Block> block_;
  std::vector<uint64_t> lastSeen_;
  std::vector<uint32_t> resident_;  // cells holding a block
  std::vector<uint32_t> pos_;       // a resident cell's index in resident_
  uint64_t frame_ = 0;
};

}  // namespace sa
