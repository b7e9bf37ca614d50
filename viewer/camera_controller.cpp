#include "viewer/camera_controller.h"

#include <algorithm>
#include <cmath>

namespace sa {

Eigen::Vector3d CameraController::unproject(double px, double py, double depth) const {
  const Eigen::Vector3d d = cam_.rayDirection(px, py);
  return cam_.eye + d * (depth / d.dot(cam_.forward()));
}

bool CameraController::project(const Eigen::Vector3d& p, double& px, double& py) const {
  const Eigen::Vector3d v = p - cam_.eye;
  const double z = v.dot(cam_.forward());
  if (z <= 0) return false;
  const double t = std::tan(cam_.fovDeg * M_PI / 360.0);
  const double aspect = double(cam_.width) / cam_.height;
  px = (v.dot(cam_.right()) / (z * t * aspect) * 0.5 + 0.5) * cam_.width;
  py = (0.5 - v.dot(cam_.trueUp()) / (z * t) * 0.5) * cam_.height;
  return true;
}

void CameraController::orbit(const Eigen::Vector3d& pivot, double dx, double dy) {
  const double radPerPixel = M_PI / std::max(cam_.height, 1);
  const Eigen::Vector3d up = cam_.up.normalized();
  // Tilt, limited so the view never flips over the pole.
  const Eigen::Vector3d f = cam_.forward();
  const double elevation = std::asin(std::clamp(-f.dot(up), -1.0, 1.0));
  const double limit = 89.0 * M_PI / 180;
  const double tilt = std::clamp(elevation + dy * radPerPixel, -limit, limit) - elevation;
  const Eigen::AngleAxisd yaw(-dx * radPerPixel, up);
  const Eigen::AngleAxisd pitch(-tilt, cam_.right());
  const Eigen::Matrix3d r = (yaw * pitch).toRotationMatrix();
  cam_.eye = pivot + r * (cam_.eye - pivot);
  cam_.target = pivot + r * (cam_.target - pivot);
}

void CameraController::pan(double dx, double dy, double depth) {
  const double worldPerPixel = 2 * depth * std::tan(cam_.fovDeg * M_PI / 360.0) / cam_.height;
  const Eigen::Vector3d shift = (-dx * cam_.right() + dy * cam_.trueUp()) * worldPerPixel;
  cam_.eye += shift;
  cam_.target += shift;
}

void CameraController::zoomToCursor(double px, double py, double depth, double factor) {
  const Eigen::Vector3d p = unproject(px, py, depth);
  // Moving the eye along the ray through the cursor keeps the direction to p, hence its pixel.
  const Eigen::Vector3d shift = (p - cam_.eye) * (1 - factor);
  cam_.eye += shift;
  cam_.target += shift;
}

void CameraController::fly(double forward, double right, double up) {
  const Eigen::Vector3d shift = forward * cam_.forward() + right * cam_.right() + up * cam_.up.normalized();
  cam_.eye += shift;
  cam_.target += shift;
}

void CameraController::frameAll(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  const Eigen::Vector3d c = (lo + hi) / 2;
  const double r = std::max({(hi - lo).norm() / 2, 1e-12, 1e-9 * c.cwiseAbs().maxCoeff()});
  const double half = std::min(cam_.fovDeg, cam_.fovDeg * cam_.width / double(cam_.height)) * M_PI / 360.0;
  const Eigen::Vector3d dir = cam_.forward();
  cam_.target = c;
  cam_.eye = c - dir * (r / std::sin(half) * 1.02);
}

void CameraController::preset(Preset p, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  const Eigen::Vector3d up = cam_.up.normalized();
  const Eigen::Vector3d side = (std::abs(up.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitZ()).cross(up).normalized();
  const Eigen::Vector3d front = up.cross(side);
  // View direction: down the up axis (tilted a hair so "up" stays defined), or level.
  const Eigen::Vector3d dir = p == Preset::kTop ? Eigen::Vector3d(-up + 1e-6 * front)
                              : p == Preset::kFront ? Eigen::Vector3d(-front) : Eigen::Vector3d(-side);
  cam_.target = cam_.eye + dir.normalized();
  frameAll(lo, hi);
}

}  // namespace sa
