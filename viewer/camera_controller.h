// Interactive camera maths, GL-free and in double (so there is no jitter at georeferenced
// coordinates): orbit about a pivot, pan, zoom toward the point under the cursor, fly,
// frame-all and preset views. Used by the window; unit-tested on its own.
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "viewer/camera.h"

namespace sa {

class CameraController {
 public:
  CameraController() = default;
  explicit CameraController(const Camera& c) : cam_(c) {}

  const Camera& camera() const { return cam_; }
  Camera& camera() { return cam_; }
  void setViewport(int width, int height) {
    cam_.width = width;
    cam_.height = height;
  }

  // Orbit about `pivot` by pixel deltas: horizontal turns about the up axis, vertical tilts
  // (stopping short of the poles). The pivot keeps its place on screen.
  void orbit(const Eigen::Vector3d& pivot, double dxPixels, double dyPixels);
  // Moves eye and target in the view plane so that the scene follows the cursor at the
  // depth `depth` (distance along the forward axis of the dragged point).
  void pan(double dxPixels, double dyPixels, double depth);
  // Moves the eye toward (factor < 1) or away from (factor > 1) the point under pixel
  // (px, py) at forward depth `depth`: that point stays under the cursor.
  void zoomToCursor(double px, double py, double depth, double factor);
  // Fly: moves eye and target along the view axes by world distances.
  void fly(double forward, double right, double up);
  // Frames the box: looks at its centre from the current direction, whole box in view.
  void frameAll(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi);
  enum class Preset { kTop, kFront, kSide };
  void preset(Preset p, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi);

  // World point seen at pixel (px, py) at forward depth `depth` (as written by the renderer).
  Eigen::Vector3d unproject(double px, double py, double depth) const;
  // Pixel coordinates of a world point (x right, y down); false when behind the camera.
  bool project(const Eigen::Vector3d& p, double& px, double& py) const;

 private:
  Camera cam_;
};

}  // namespace sa
