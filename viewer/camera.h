// Cameras in world coordinates (double), and the camera-relative matrices the GPU gets: the
// view is a pure rotation about the eye, so no absolute coordinate ever reaches float32.
#pragma once
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/error.h"

namespace sa {

struct Camera {
  Eigen::Vector3d eye = Eigen::Vector3d(0, 0, 1);
  Eigen::Vector3d target = Eigen::Vector3d::Zero();
  Eigen::Vector3d up = Eigen::Vector3d::UnitY();
  double fovDeg = 40;  // vertical field of view
  int width = 512, height = 512;

  Eigen::Vector3d forward() const { return (target - eye).normalized(); }
  Eigen::Vector3d right() const { return forward().cross(up).normalized(); }
  Eigen::Vector3d trueUp() const { return right().cross(forward()); }
  // Rotation rows: right, up, -forward (OpenGL view space looks down -z).
  Eigen::Matrix3d viewRotation() const;
  // Infinite reverse-Z perspective (depth = near / distance, with glClipControl 0..1).
  Eigen::Matrix4d projection(double nearPlane) const;
  // World-space ray direction through pixel centre (px + 0.5, py + 0.5), py from the top.
  Eigen::Vector3d rayDirection(double px, double py) const;
  Status validate() const;
};

// N cameras on a circle around the bounding box (about `up`), 20° above its centre plane,
// far enough that the bounding sphere fits the view.
std::vector<Camera> orbitCameras(const Eigen::Vector3d& boxMin, const Eigen::Vector3d& boxMax, int count,
                                 const Eigen::Vector3d& up, double fovDeg, int width, int height);

}  // namespace sa
