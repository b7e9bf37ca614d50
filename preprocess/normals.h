// Neighbour queries: outlier removal, normal estimation and moving-least-squares smoothing over
// the k nearest neighbours (GridKnn, a uniform grid: faster than a kd-tree on scan surfaces),
// and the sample-spacing estimate that sets texel sizes and coverage radii (FLANN on a few
// sub-cubes).
#pragma once
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include <Eigen/Core>

namespace sa {

// How estimated normals get their sign.
struct NormalOrientation {
  // Per scan index: direction toward the scanner (scan sets). When empty, normals point
  // away from `center` (a plain cloud: "toward the outside").
  std::vector<Eigen::Vector3d> towardScanner;
  const uint16_t* scan = nullptr;  // per point scan index, stride `scanStride` bytes
  size_t scanStride = 0;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();  // relative to the same origin as pos
  // A cloud that is one open sheet (a wall, a field: nearly planar overall) has no outside to
  // point away from; its normals all take this side instead (zero: not a sheet).
  Eigen::Vector3d sheetSide = Eigen::Vector3d::Zero();
};

struct SurfaceOptions {
  int neighbours = 24;        // k nearest neighbours per point
  bool estimateNormals = true;  // false: nrm holds the file's normals (their sign orients the fit)
  bool smooth = true;           // move points onto their moving-least-squares surface
  // A point whose mean distance to its 8 nearest neighbours exceeds this many times the
  // median of its neighbours' is an outlier (0: keep all).
  double outlierRatio = 3;
  // The points' spacing when the caller has it (estimateSpacing(pos, n): its area spacing, else
  // its nearest), which sizes the neighbour grid; 0: estimated here.
  double spacing = 0;
  // Lay the points out in the neighbour grid's order (by cell, the cells in Morton order)
  // before the fit, so that it reads and writes nearby memory: pos and nrm are permuted in place
  // (the point now at i was at (*order)[i], fitSurface's order must be given), and keep and
  // localSpacing come in that order. The caller permutes its other per-point arrays.
  bool layOut = false;
  // Points from this index on (in the caller's order) are neighbours only: the fit and the
  // outlier test read them, but they get no fit of their own and are flagged 0 in keep (a
  // chunk's halo, preprocess/chunk_halo.h). They are not counted as outliers.
  size_t neighboursFrom = SIZE_MAX;
  // Progress of long fits, called now and then from any thread with the units done since the
  // last call; the whole fit is 2 units a point. May be empty.
  std::function<void(size_t)> progress;
  // Per point (in localSpacing's order; may be null): set to 1 where the fit found a clean
  // surface around the point (neighbours within kSurfaceResidual of their radius from the
  // quadric, the point not at the neighbourhood's edge), else left as the caller set it. Such a
  // point's radii may follow its spacing far past the pack's (a sparsely sampled surface:
  // water, a scan's far field); loose returns (vegetation) and edges keep theirs near it.
  uint8_t* surfaceLike = nullptr;
};

// The surface test of SurfaceOptions::surfaceLike: the neighbours' weighted RMS distance to the
// point's quadric against the distance to its farthest neighbour.
constexpr double kSurfaceResidual = 0.05;

// The surface through a chunk's points, from one k-nearest-neighbour query per point (GridKnn):
// outliers (flagged 0 in keep), unit normals (PCA of the neighbourhood refined by the MLS
// quadric, oriented toward the scanner, the file's normal or away from the centre) and, with
// opt.smooth, positions moved onto the MLS surface where it is one (noise of merged scans
// averaged out). pos: n xyz-interleaved positions (updated); nrm: n normals (in/out). Points
// whose neighbourhood is degenerate keep their position and get a zero normal when estimated.
// An outlier's position and normal are left as the fit made them (callers drop outliers).
// Returns the number of outliers.
// localSpacing (may be null): per point, the side of its area, r_8 sqrt(pi / 8) (Spacing::area);
// written for every point (callers may pass memory they have not initialized).
// order (may be null): the points in the neighbour grid's order (SurfaceOptions::layOut).
size_t fitSurface(double* pos, size_t n, const NormalOrientation& orient, const SurfaceOptions& opt, float* nrm,
                  std::vector<uint8_t>& keep, float* localSpacing = nullptr, std::vector<uint32_t>* order = nullptr);

// pos: n xyz-interleaved positions. Writes n unit normals (xyz-interleaved) into nrm.
// Points with fewer than 3 distinct neighbours get a zero normal (unknown).
void estimateNormals(const double* pos, size_t n, int k, const NormalOrientation& orient, float* nrm);

struct Spacing {
  double nearest = 0;  // median distance to the nearest other point: the sample spacing
  // Median side of the area per point, r_8 sqrt(pi / 8) with r_8 the distance to the 8th
  // nearest neighbour: like `nearest` on an even grid, larger where samples come in lines
  // (airborne lidar's scan lines, a turntable scanner's profiles), where the nearest neighbour
  // sees only the spacing along a line.
  double area = 0;
};

// Over up to `samples` evenly spread points.
Spacing estimateSpacing(const double* pos, size_t n, size_t samples = 4096);

}  // namespace sa
