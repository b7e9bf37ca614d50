// Octree decomposition into height fields with the PCA test of Lu, Low & Zheng §3.1.2: a cell
// is a height field when no point's normal faces away from the best-fit plane's normal W
// (W's sign chosen to agree with the normals); otherwise it splits into 8, down to maxDepth.
#pragma once
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace sa {

inline constexpr double kPointOutlierFraction = 0.01;
inline constexpr uint32_t kPointMinSplit = 32, kMeshMinSplit = 4;

struct OctreeParams {
  int maxDepth = 10;          // global octree level limit (0 = the root cube)
  double maxAngleDeg = 85.0;  // largest angle allowed between a normal and W (paper: 90)
  // Cells with fewer points are never split (kept, flagged forced). 0 = by input (the pack
  // pipeline): kPointMinSplit for points (normals from 24 neighbours: smaller cells know nothing
  // more), kMeshMinSplit for meshes (a thin fin of a few vertices whose faces fail the test must
  // split, or one of its faces has no cell and leaves a hole).
  uint32_t minSplitPoints = 0;
  // Fraction of a cell's points whose normal may fail the test (estimated normals of merged,
  // slightly misaligned scans are noisy; a strict test then splits flat regions for nothing).
  // Negative = by input (the pack pipeline): 0 for meshes (exact normals: the few vertices that
  // fail are a fold, such as the underside of a dragon's scale over the next one), else
  // kPointOutlierFraction.
  double outlierFraction = -1;
  // The layer test (0 = off): over the best-fit plane, in square bins of side layerBin, a bin
  // whose points' heights leave a gap wider than layerGap is layered (canopy over ground, a
  // deck over water); a cell with layeredBins or more such bins is not a height field,
  // whatever its normals say. Both in world units, set from the sample spacing.
  double layerBin = 0, layerGap = 0;
  uint32_t layeredBins = 3;
  // A height-field cell with more points is split all the same (0: no limit): bounds the
  // working memory of the cell's tile (the pack pipeline sets it from --mem-budget).
  uint32_t maxLeafPoints = 0;
};

struct PlaneFit {
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  Eigen::Vector3d u = Eigen::Vector3d::UnitX(), v = Eigen::Vector3d::UnitY(), w = Eigen::Vector3d::UnitZ();
  bool degenerate = false;   // < 3 distinct points or collinear: frame from the normals
  bool heightField = false;  // passed the normal test
  double minCos = 1;         // smallest n·W over the cell's points with a valid normal
  uint32_t violations = 0;   // points whose normal fails the test
  bool layered = false;      // failed the layer test (normals passed)
};

// PCA plane of the points idx[0..n) (positions xyz-interleaved, normals likewise; a normal
// of zero length counts as unknown) and the height-field test. Never produces NaN: single
// points, duplicates and collinear sets fall back to a frame built from the mean normal.
// cone (may be null): per point, the half-angle (radians) of a cone about its normal holding
// every direction the test must pass (a mesh vertex's incident faces): a point passes when
// its normal's angle to W plus its cone is within acos(cosMax).
PlaneFit fitPlane(const double* pos, const float* nrm, const uint32_t* idx, size_t n, double cosMax,
                  double outlierFraction = 0, const float* cone = nullptr);

// Number of layered bins (see OctreeParams::layerBin), counting up to `enough`.
uint32_t countLayeredBins(const double* pos, const uint32_t* idx, size_t n, const PlaneFit& fit, double bin,
                          double gap, uint32_t enough);

struct OctreeCell {
  PlaneFit fit;
  uint32_t first = 0, count = 0;  // range in the permuted index array
  int level = 0;
  bool forced = false;            // failed the test but could not split further
  Eigen::Vector3d cubeMin;        // the octree cell's cube (relative to the pack origin)
  double cubeSize = 0;
};

// Reorders idx[b..e) so that the indices whose point's coordinate `axis` is below `mid` come
// first; returns where the others begin. The order is std::partition's (the k-th index that
// must move right trades places with the k-th from the end that must move left), so octrees
// are the same as before; large ranges are tested, counted and swapped on every core.
uint32_t* partitionBelow(uint32_t* b, uint32_t* e, const double* pos, int axis, double mid);

// Subdivides the cube (cubeMin, cubeSize, at octree level `level`) holding points idx.
// Permutes idx so every emitted cell's points are contiguous; appends cells to `out`.
// cone: as fitPlane's (may be null).
void buildOctree(const double* pos, const float* nrm, std::vector<uint32_t>& idx,
                 const Eigen::Vector3d& cubeMin, double cubeSize, int level, const OctreeParams& params,
                 std::vector<OctreeCell>& out, const float* cone = nullptr);

}  // namespace sa
