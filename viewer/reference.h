// Reference renders of the original data, for accuracy checks: a triangle mesh rasterized on
// the CPU in double precision with the same camera as the GPU render (exact geometry).
#pragma once
#include <string>
#include <vector>

#include "viewer/camera.h"

namespace sa {

struct TriangleMesh {
  std::vector<double> positions;  // xyz per vertex, world coordinates
  std::vector<uint32_t> indices;  // 3 per triangle
};

Result<TriangleMesh> loadMesh(const std::string& path);

// Linear view depth (distance along the forward axis) per pixel, row 0 at the top; +inf
// where no triangle covers the pixel centre.
std::vector<float> referenceDepth(const TriangleMesh& mesh, const Camera& cam);

struct DepthComparison {
  double iou = 0;                // coverage intersection over union
  double medianRelError = 0;     // |d_test - d_ref| / diagonal over pixels both cover
  double p95RelError = 0;
  size_t both = 0, onlyTest = 0, onlyRef = 0;
};

DepthComparison compareDepth(const std::vector<float>& test, const std::vector<float>& ref, double diagonal);

}  // namespace sa
