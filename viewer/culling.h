// Per-frame visibility on the CPU, in double precision and camera-relative: which cells'
// boxes are drawn, how (front faces when the camera is outside the box, back faces when it
// is inside, a single splat when the box covers less than about a pixel), with how many
// ray-march steps, and in which order (front to back, for early depth rejection).
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "atlas/pack_format.h"
#include "viewer/camera.h"

namespace sa {

// The default bound on a fragment's linear ray-march steps (--iterations). A fragment takes
// one step per 1.5 texels its ray crosses, up to this: at 12 a grazing ray over a 100-texel
// tile stepped 8 texels at a time over thin ridges (47 of the dragon's 88 pinholes over 32
// views at 1024x1024); 64 covers a 96-texel crossing, for about 20 % more frame time.
inline constexpr int kDefaultIterations = 64;

struct CullOptions {
  bool frustum = true;         // drop boxes outside the view frustum
  bool backfaceCull = true;    // rasterize front faces only (back faces where the camera is inside)
  bool adaptiveSteps = true;   // steps from projected size and view angle, bounded by maxSteps
  bool subpixelSplats = true;  // boxes under splatPixels drawn as one splat
  bool frontToBack = true;     // sort boxes by distance
  int maxSteps = kDefaultIterations;
  int minSteps = 4;
  double splatPixels = 1.0;
  // --mode auto: boxes whose projected diameter is under this many pixels go to `sliced` (0: none).
  double slicePixels = 0;
  // Clip box and section plane (relative to the pack origin): boxes wholly outside are culled.
  bool clipBox = false;
  Eigen::Vector3d clipLo = Eigen::Vector3d::Zero(), clipHi = Eigen::Vector3d::Zero();
  bool clipPlane = false;
  Eigen::Vector3d planePoint = Eigen::Vector3d::Zero(), planeNormal = Eigen::Vector3d::UnitZ();
  // Tiles still streaming to the GPU: a cell with cellResident[cell] == 0 is not drawn this
  // frame but listed in VisibleSet::missing (null: every cell is resident).
  const uint8_t* cellResident = nullptr;
};

struct DrawItem {
  uint32_t cell;
  uint32_t steps;  // linear-search steps for this box
};
static_assert(sizeof(DrawItem) == 8);

struct VisibleSet {
  std::vector<DrawItem> front;   // camera outside the box: rasterize front faces
  std::vector<DrawItem> inside;  // camera inside (or touching) the box: back faces
  std::vector<DrawItem> splats;  // sub-pixel boxes
  std::vector<DrawItem> sliced;  // --mode auto: boxes under CullOptions::slicePixels, drawn as slices
  std::vector<uint32_t> missing; // visible cells whose tiles are not resident (CullOptions::cellResident), nearest first
  uint32_t submitted = 0, culled = 0;
};

class CellCuller {
 public:
  explicit CellCuller(std::span<const CellRecord> cells);
  // eyeRel: the camera position relative to the pack origin. nearPlane as in the projection.
  void compute(const Camera& cam, const Eigen::Vector3d& eyeRel, double nearPlane, const CullOptions& opt,
               VisibleSet& out) const;

 private:
  struct Bounds {
    Eigen::Vector3d center, origin, u, v, w;
    double radius;
    double box[6];
  };
  std::vector<Bounds> bounds_;
};

}  // namespace sa
