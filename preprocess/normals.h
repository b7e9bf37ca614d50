// Neighbour queries with FLANN (kd-tree): normal estimation by PCA over the k nearest
// neighbours, and the sample-spacing estimate that sets texel sizes and coverage radii.
#pragma once
#include <cstddef>
#include <cstdint>
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
};

// pos: n xyz-interleaved positions. Writes n unit normals (xyz-interleaved) into nrm.
// Points with fewer than 3 distinct neighbours get a zero normal (unknown).
void estimateNormals(const double* pos, size_t n, int k, const NormalOrientation& orient, float* nrm);

// Median distance to the nearest other point over up to `samples` evenly spread points.
double estimateSpacing(const double* pos, size_t n, size_t samples = 4096);

}  // namespace sa
