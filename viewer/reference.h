// Reference renders of the original data, for accuracy checks (tests and `scanatlas eval`):
// triangles rasterized on the CPU in double precision with the same camera as the GPU render.
// References are a triangle mesh (PLY with faces) or a Stanford scan set (.conf), whose range
// grids are triangulated: neighbouring grid samples, edges longer than a maximum dropped.
#pragma once
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "viewer/camera.h"
#include "viewer/image_io.h"

namespace sa {

struct TriangleMesh {
  std::vector<double> positions;  // xyz per vertex, world coordinates
  std::vector<uint32_t> indices;  // 3 per triangle
  std::string description;        // what the reference is, for reports
};

Result<TriangleMesh> loadMesh(const std::string& path);
// A mesh PLY, or a .conf scan set triangulated from its range grids (maxEdge <= 0: three
// times the median grid edge).
Result<TriangleMesh> loadReference(const std::string& path, double maxEdge = 0);

// Linear view depth (distance along the forward axis) per pixel, row 0 at the top; +inf
// where no triangle covers the pixel centre.
std::vector<float> referenceDepth(const TriangleMesh& mesh, const Camera& cam);

struct ReferenceView {
  std::vector<float> depth;    // as referenceDepth
  std::vector<float> normals;  // unit face normal (xyz) of the visible triangle; 0 where none
};
ReferenceView referenceView(const TriangleMesh& mesh, const Camera& cam);

// The viewer's shading (Lambert, head light; shading.glsl) applied to a reference view.
Image shadeReference(const ReferenceView& v, const Camera& cam, const float baseColor[3], const float background[3]);

struct DepthComparison {
  double iou = 0;                // coverage intersection over union
  double medianRelError = 0;     // |d_test - d_ref| / diagonal over pixels both cover
  double p95RelError = 0;
  size_t both = 0, onlyTest = 0, onlyRef = 0;
};

DepthComparison compareDepth(const std::vector<float>& test, const std::vector<float>& ref, double diagonal);

}  // namespace sa
