// The `gdm` mode's core (MODES.md §2; Wang et al., "Generalized Displacement Maps", 2004), for the
// cells that are not height fields (forced cells: overhangs, thin parts, layers), GL-free.
//
// What is built: per forced cell a grid over its box (the cell's texel in u and v, the smaller of
// the two in w) holding, at the voxels' corners, a signed distance to the surface of the cell's
// SOURCE samples, never its height map, negative inside: for points, the distance to the algebraic
// sphere fitted to the oriented samples around the corner (APSS, Guennebaud & Gross 2007), for
// triangles' samples the implicit moving-least-squares field (Kolluri 2008; Hoppe et al. 1992),
// f(x) = sum_i w_i (x - p_i) . n_i / sum_i w_i; Gaussian weights a sample spacing wide or more. Corners farther than a band of about
// two spacings from every sample are unknown (nothing is invented far from the data). The surface
// is where the trilinear interpolation of the corners is zero: continuous from voxel to voxel,
// both sides of thin parts apart (their normals face away from each other), the noise of merged
// scans averaged out. The 3-D DDA (Amanatides & Woo) finds the first crossing along a ray entering
// through any face or starting inside the box. On top of the grid,
// the generalized displacement function (000 §3.1): for every voxel centre and 16 x 32 directions
// over the full sphere, the distance to the first voxel the surface may pass (a lower bound over
// the bin's neighbours and the voxel's face neighbours), SVD-compressed (000 §4.1) with the rank
// chosen by its error; a ray that crosses many voxels jumps by it a few times, each jump checked
// against the voxels half a voxel before it lands, and walks the DDA from there.
#pragma once
#include <algorithm>
#include <cstdint>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "atlas/pack_file.h"
#include "common/error.h"

namespace sa::gdm {

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

// A corner's signed distance in units of CellGrid::unit(); kUnknown: no sample near it.
inline constexpr int16_t kUnknown = -32768;
// A voxel's state: a corner unknown; all eight known and positive (no surface can pass); all
// known and one on or under zero (the surface passes, or the voxel is inside: "occupied").
enum : uint8_t { kVoxelUnknown = 0, kVoxelOutside = 1, kVoxelOccupied = 3 };

struct CellGrid {
  uint32_t cell = 0;
  int nx = 0, ny = 0, nz = 0;
  double vx = 0, vy = 0, vz = 0;   // voxel sizes (frame units)
  std::vector<int16_t> corners;    // (nx + 1)(ny + 1)(nz + 1), x fastest, then y, then z
  std::vector<uint8_t> state;      // per voxel, x fastest, then y, then z
  Function fn;
  double kernel = 0;  // the bake's kernel width in sample spacings (0: from triangles); not stored
  double unit() const { return std::min(vx, std::min(vy, vz)) / 1024; }  // of the corner values
  size_t voxelCount() const { return size_t(nx) * ny * nz; }
  size_t cornerIndex(int x, int y, int z) const { return (size_t(z) * (ny + 1) + y) * (nx + 1) + x; }
  uint8_t at(int x, int y, int z) const { return state[(size_t(z) * ny + y) * nx + x]; }
  bool occupied(int x, int y, int z) const { return at(x, y, z) == kVoxelOccupied; }
};

// A signed distance (frame units) as a corner value of g (clamped to 32 voxels either way).
int16_t quantizeCorner(const CellGrid& g, double f);
// Sets g.state from g.corners.
void finishStates(CellGrid& g);

// Source samples of one cell, in its frame: positions, and normals where known (zero: unknown).
struct Samples {
  std::vector<Eigen::Vector3d> p, n;
};

// Builds a cell's grid from its samples (those without a normal are left out); spacing: the
// sample spacing of points, 0 for samples taken densely from triangles. The kernel is a spacing
// wide, widened (up to kMaxKernel) where the samples' noise about the field is large, until the
// field keeps kFieldNoise spacings of it (CellGrid::kernel says how wide). Points fit spheres, whose
// surface stays on a curved part however wide the kernel (a plane's bulges out by h^2 / 2R).
inline constexpr double kFieldNoise = 0.02, kMaxKernel = 3;
CellGrid buildGrid(const CellRecord& c, uint32_t cell, const Samples& s, double spacing);

// First crossing of the surface along o + t d (frame), t in [t0, t1], either way (a camera inside a
// thin part sees its walls); normal (frame, the field's gradient turned to face the ray's origin);
// touched: whether the ray
// passed a known voxel, one near the samples (the shader draws the cell's height field where it
// passed none: the samples were too sparse there for the band to reach).
bool trace(const CellRecord& c, const CellGrid& g, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t0, double t1,
           double& tHit, Eigen::Vector3d* normal = nullptr, uint32_t* steps = nullptr, bool* touched = nullptr);

// The function's raw values (rows x cols, as Function describes), by walking every voxel centre
// along every bin's central direction.
std::vector<float> sampleFunction(const CellGrid& g);
// Computes g.fn: the rank-k truncated SVD of sampleFunction(g), the smallest k <= kMaxRank whose
// p95 error is at most maxError voxels (else kMaxRank); none when the grid is larger than the
// bake allows (more than maxEntries values, or more than 2048 columns) or too small for any ray
// to cross kDirectVoxels voxels (nx + ny + nz below it: the function would never be read).
void bakeFunction(CellGrid& g, double maxError = 0.5, uint64_t maxEntries = uint64_t(1) << 25);
// How many voxels random rays through the box (any direction) cross before the first known
// voxel, on average: what the function could let them skip.
double skippableVoxels(const CellRecord& c, const CellGrid& g, int rays = 64);
// The function at voxel (x, y, z) for direction d (frame, any length): the nearest bin's value.
double lookup(const CellGrid& g, int x, int y, int z, const Eigen::Vector3d& d);

// What the function-guided trace did (the shader's counters): walked without a lookup (no
// function, or a ray crossing fewer than kDirectVoxels voxels: the walk is as cheap as lookups),
// a hit or a miss after its jumps, or a jump refused by its check (then walked from where the
// ray was).
enum class Guided { kNone, kHit, kMiss, kFallback };
inline constexpr int kDirectVoxels = 12, kMaxJumps = 4;
inline constexpr double kWorthAFunction = 6;  // voxels a ray would skip, on average (buildForcedGrids)
// The shader's cast in double: with a function and a long enough ray, up to kMaxJumps lookups,
// each jumping from the voxel the ray has reached by the function's value less half a voxel,
// each taken only where the voxel half a voxel before its landing point is empty; then the DDA
// from there, as trace (hits count from t0).
bool traceGuided(const CellRecord& c, const CellGrid& g, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t0,
                 double t1, double& tHit, Eigen::Vector3d* normal, uint32_t* steps, bool* touched, Guided* how = nullptr);

// Reads the pack's sources (NOTE) and builds every forced cell's grid. Points without normals in
// their files get the pack's own estimate (preprocess fitSurface: outliers left out, normals
// toward the scanner of a scan set or away from the centre, not smoothed). Then the direction
// functions, where random rays would skip kWorthAFunction voxels or more on average
// (skippableVoxels), most skipped first, while their bytes fit functionBudget. progress(done,
// total).
struct FunctionReport {
  uint32_t candidates = 0, baked = 0, overBudget = 0;
  uint64_t bytes = 0;
};
inline constexpr uint64_t kDefaultFunctionBudget = uint64_t(32) << 20;
// The bytes of a grid's function in the section.
uint64_t functionBytes(const CellGrid& g);
// Bakes the functions of the grids whose rays would skip (skip[k], skippableVoxels) at least
// kWorthAFunction voxels, most skipped first, in batches of 16; a function is kept while the
// functions' bytes stay within budget, the others get none; after a batch that kept none the rest
// are left out unbaked. tick (may be empty): once per grid.
void bakeFunctions(std::vector<CellGrid>& grids, const std::vector<double>& skip, uint64_t budget, FunctionReport* report,
                   const std::function<void()>& tick = nullptr);
Result<std::vector<CellGrid>> buildForcedGrids(const PackReader& pack, uint64_t functionBudget = kDefaultFunctionBudget,
                                               FunctionReport* report = nullptr,
                                               const std::function<void(uint64_t, uint64_t)>& progress = nullptr);

// The pack section `GDMV` (docs/FORMAT.md).
inline constexpr char kSectionId[4] = {'G', 'D', 'M', 'V'};
inline constexpr uint32_t kSectionVersion = 3;  // 1: surfels only; 2: surfels and the function
inline constexpr uint32_t kNoEntry = 0xffffffffu;
// nx, ny, nz, vx, vy, vz (f32 bits), the function's rank, the first word of its u (from the block's
// start); then the voxel states (2 bits each, 16 to a word, low bits first), then the corners (16
// bits each, two to a word, low half first), then the function.
inline constexpr int kBlockHeaderWords = 8;
inline uint64_t stateWords(uint64_t voxels) { return (voxels + 15) / 16; }
inline uint64_t cornerWords(uint64_t corners) { return (corners + 1) / 2; }
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
