// Image error of a render against a reference view of the original data (docs/BENCHMARKS.md):
// coverage IoU, silhouette error, depth error relative to the bounding-box diagonal, normal
// angular error and PSNR of the shaded image.
#pragma once
#include <vector>

#include "viewer/reference.h"

namespace sa {

struct ViewMetrics {
  double iou = 0;
  double silhouetteError = 0;   // pixels whose coverage differs / reference silhouette perimeter (pixels)
  double depthMedian = 0, depthP95 = 0;  // relative to the diagonal, over pixels both cover
  double normalMedianDeg = -1;  // -1 when the render has no normals (points mode)
  double psnr = 0;              // dB, RGB over the whole image
  size_t both = 0, onlyTest = 0, onlyRef = 0;
  // Pixels where the reference has surface on the pixel and all 8 neighbours, and the render
  // has none: holes inside the surface (pinholes, seams), not silhouette differences.
  size_t interiorHoles = 0;
  std::vector<double> depthErrors;   // per pixel both cover, relative (for pooling)
  std::vector<double> normalErrors;  // degrees
};

// test: the render's colour, linear depth and (optional, may be empty) world normals.
ViewMetrics evaluateView(const Image& testColor, const std::vector<float>& testDepth,
                         const std::vector<float>& testNormals, const ReferenceView& ref, const Image& refShaded,
                         double diagonal);

double percentile(std::vector<double> v, double q);

// Two renders of one view by the same pack (e.g. under --gpu-budget against everything
// resident): coverage IoU and the depth difference over pixels both cover, in `unit`s (texels).
struct RenderAgreement {
  double iou = 1, depthMedian = 0, depthP95 = 0;
  size_t both = 0, onlyA = 0, onlyB = 0;
};
RenderAgreement compareRenders(const std::vector<float>& depthA, const std::vector<float>& depthB, double unit);

// Shading continuity across cell borders: the mean angle between the shading normals of
// neighbouring pixels (right and down) drawn by different cells, against the same for
// neighbouring pixels of one cell. Only pairs on one continuous surface count: both hit, depths
// within a few pixel footprints (no silhouettes or occlusion edges).
struct SeamStats {
  double borderMeanDeg = 0, insideMeanDeg = 0;
  size_t borderPairs = 0, insidePairs = 0;
  double ratio() const { return insideMeanDeg > 0 ? borderMeanDeg / insideMeanDeg : 0; }
};
SeamStats seamStats(const Camera& cam, const std::vector<float>& depth, const std::vector<float>& normals,
                    const std::vector<uint32_t>& cells);

// The hit point of every pixel with finite linear depth (row 0 at the top), relative to
// `origin`, xyz interleaved, formed in double from the camera.
std::vector<double> surfacePoints(const Camera& cam, const std::vector<float>& depth, const Eigen::Vector3d& origin);

}  // namespace sa
