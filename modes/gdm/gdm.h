// The `gdm` mode's core (MODES.md §2; Wang et al., "Generalized Displacement Maps", 2004), for the
// cells that are not height fields (forced cells: overhangs, thin parts, layers), GL-free.
//
// What is built: per forced cell a voxel grid over its box (the cell's texel in u and v, the
// smaller of the two in w) whose occupied voxels each hold a surfel - the plane of the cell's
// SOURCE samples near the voxel (points: every voxel within 0.75 sample spacings of a point;
// triangles: samples half a voxel apart), never its height map - and the 3-D DDA
// (Amanatides & Woo) that finds the first surfel along a ray entering through any face or
// starting inside the box. On top of the grid, the generalized displacement function (000 §3.1):
// for every voxel centre and 16 x 32 directions over the full sphere, the distance to the first
// occupied voxel (a lower bound over the bin's neighbours and the voxel's face neighbours),
// SVD-compressed (000 §4.1) with the rank chosen by its error; a ray that crosses many voxels
// jumps by it a few times, each jump checked against the occupancy half a voxel before it lands,
// and walks the DDA from there.
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
// The generalized displacement function of a grid, compressed: M[row][col] ~ sum_k u[row][k]
// v[col][k], row = (y nx + x) kPhiBins + phi bin, col = z kThetaBins + theta bin; a value is the
// distance from the voxel centre along the bin's central direction to where the ray enters the
// first occupied voxel (0 inside one), or to the box where it meets none, in units of the
// smallest voxel side. Directions (cell frame): theta from +w, bin i centred at (i + 1/2) pi / 16;
// phi = atan2(v, u), bin j centred at 2 pi j / 32. u and v hold IEEE half values (as stored).
inline constexpr int kThetaBins = 16, kPhiBins = 32, kMaxRank = 16;
struct Function {
  int rank = 0;  // 0: none (too large for the bake's limits: the DDA alone)
  std::vector<float> u, v;
  double p95 = 0, p99 = 0;  // reconstruction error over every entry (voxel units)
};

struct CellGrid {
  uint32_t cell = 0;
  int nx = 0, ny = 0, nz = 0;
  double vx = 0, vy = 0, vz = 0;  // voxel sizes (frame units)
  std::vector<uint32_t> voxels;   // x fastest, then y, then z
  Function fn;
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

// The function's raw values (rows x cols, as Function describes), by walking every voxel centre
// along every bin's central direction.
std::vector<float> sampleFunction(const CellGrid& g);
// Computes g.fn: the rank-k truncated SVD of sampleFunction(g), the smallest k <= kMaxRank whose
// p95 error is at most maxError voxels (else kMaxRank); none when the grid is larger than the
// bake allows (more than maxEntries values, or more than 2048 columns).
void bakeFunction(CellGrid& g, double maxError = 0.5, uint64_t maxEntries = uint64_t(1) << 25);
// The function at voxel (x, y, z) for direction d (frame, any length): the nearest bin's value.
double lookup(const CellGrid& g, int x, int y, int z, const Eigen::Vector3d& d);

// What the function-guided trace did (the shader's counters): walked without a lookup (no
// function, or a ray crossing fewer than kDirectVoxels voxels: the walk is as cheap as lookups),
// a hit or a miss after its jumps, or a jump refused by its check (then walked from where the
// ray was).
enum class Guided { kNone, kHit, kMiss, kFallback };
inline constexpr int kDirectVoxels = 12, kMaxJumps = 4;
// The shader's cast in double: with a function and a long enough ray, up to kMaxJumps lookups,
// each jumping from the voxel the ray has reached by the function's value less half a voxel,
// each taken only where the voxel half a voxel before its landing point is empty; then the DDA
// from there, as trace (hits count from t0).
bool traceGuided(const CellRecord& c, const CellGrid& g, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t0,
                 double t1, double& tHit, Eigen::Vector3d* normal, uint32_t* steps, bool* touched, Guided* how = nullptr);

// Reads the pack's sources (NOTE) and builds every forced cell's grid and its function.
// progress(done, total).
Result<std::vector<CellGrid>> buildForcedGrids(const PackReader& pack,
                                               const std::function<void(uint64_t, uint64_t)>& progress = nullptr);

// The pack section `GDMV` (docs/FORMAT.md).
inline constexpr char kSectionId[4] = {'G', 'D', 'M', 'V'};
inline constexpr uint32_t kSectionVersion = 2;  // 1: voxels only
inline constexpr uint32_t kNoEntry = 0xffffffffu;
// nx, ny, nz, vx, vy, vz (f32 bits), the function's rank, the first word of its u (from the block's start)
inline constexpr int kBlockHeaderWords = 8;
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
