// The `gdm` mode's core (MODES.md §2; Wang et al., "Generalized Displacement Maps", 2004), for the
// cells that are not height fields (forced cells: overhangs, thin parts, layers), GL-free.
//
// What is built: per forced cell a voxel grid over its box (the cell's texel in u and v, the
// smaller of the two in w) whose occupied voxels each hold a surfel - the plane of the cell's
// SOURCE samples near the voxel (points: every voxel within 0.75 sample spacings of a point;
// triangles: samples half a voxel apart), never its height map - and the 3-D DDA
// (Amanatides & Woo) that finds the first surfel along a ray entering through any face or
// starting inside the box. What is not built yet: the generalized displacement function over the
// sphere of directions and its compression (000 §3-4), which would replace most of the DDA.
#pragma once
#include <cstdint>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "atlas/pack_file.h"
#include "common/error.h"

namespace sa::gdm {

// One voxel: 0 = empty; else bits 0-15 the surfel normal (octahedral, 8 + 8 bits, frame
// coordinates), bits 16-31 the plane's offset from the voxel centre along that normal, a signed
// 16-bit fraction of half the voxel diagonal.
struct CellGrid {
  uint32_t cell = 0;
  int nx = 0, ny = 0, nz = 0;
  double vx = 0, vy = 0, vz = 0;  // voxel sizes (frame units)
  std::vector<uint32_t> voxels;   // x fastest, then y, then z
  uint32_t at(int x, int y, int z) const { return voxels[(size_t(z) * ny + y) * nx + x]; }
};

uint32_t encodeVoxel(const Eigen::Vector3d& normal, double offset, const Eigen::Vector3d& voxelSize);
void decodeVoxel(uint32_t v, const Eigen::Vector3d& voxelSize, Eigen::Vector3d& normal, double& offset);

// Source samples of one cell, in its frame: positions, and normals where known (zero: unknown).
struct Samples {
  std::vector<Eigen::Vector3d> p, n;
};

// Builds a cell's grid from its samples; spacing: the sample spacing (points: each sample
// reaches the voxels within 0.75 of it; 0 for triangle samples, which reach their own voxel).
CellGrid buildGrid(const CellRecord& c, uint32_t cell, const Samples& s, double spacing);

// First surfel along o + t d (frame), t in [t0, t1]; normal (frame, facing the ray's origin);
// touched: whether the ray passed an occupied voxel (the shader draws the cell's height field
// where it passed none).
bool trace(const CellRecord& c, const CellGrid& g, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t0, double t1,
           double& tHit, Eigen::Vector3d* normal = nullptr, uint32_t* steps = nullptr, bool* touched = nullptr);

// Reads the pack's sources (NOTE) and builds every forced cell's grid. progress(done, total).
Result<std::vector<CellGrid>> buildForcedGrids(const PackReader& pack,
                                               const std::function<void(uint64_t, uint64_t)>& progress = nullptr);

// The pack section `GDMV` (docs/FORMAT.md).
inline constexpr char kSectionId[4] = {'G', 'D', 'M', 'V'};
inline constexpr uint32_t kSectionVersion = 1;
inline constexpr uint32_t kNoEntry = 0xffffffffu;
inline constexpr int kBlockHeaderWords = 8;  // nx, ny, nz, vx, vy, vz (f32 bits), zero, zero
struct SectionHeader {
  uint32_t version, cellCount, gridCells, zero0;
  double bakeSeconds;
  uint64_t wordCount;
  uint8_t zero[32];
};
static_assert(sizeof(SectionHeader) == 64);

ExtraSection makeSection(const PackReader& pack, const std::vector<CellGrid>& grids, double bakeSeconds);

struct SectionView {
  bool present = false;
  SectionHeader header{};
  const uint32_t* entries = nullptr;
  const uint32_t* words = nullptr;
  uint64_t bytes = 0;
};
Result<SectionView> readSection(const PackReader& pack);
CellGrid gridFromSection(const PackReader& pack, const SectionView& v, uint32_t cell);

}  // namespace sa::gdm
