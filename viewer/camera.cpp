#include "viewer/camera.h"

#include <algorithm>
#include <cmath>

namespace sa {

Eigen::Matrix3d Camera::viewRotation() const {
  Eigen::Matrix3d r;
  r.row(0) = right();
  r.row(1) = trueUp();
  r.row(2) = -forward();
  return r;
}

Eigen::Matrix4d Camera::projection(double n) const {
  const double f = 1.0 / std::tan(fovDeg * M_PI / 360.0);
  const double aspect = double(width) / double(height);
  Eigen::Matrix4d p = Eigen::Matrix4d::Zero();
  p(0, 0) = f / aspect;
  p(1, 1) = f;
  p(2, 3) = n;   // clip z = near
  p(3, 2) = -1;  // clip w = -z_view = distance along forward
  return p;
}

Eigen::Vector3d Camera::rayDirection(double px, double py) const {
  const double f = std::tan(fovDeg * M_PI / 360.0);
  const double aspect = double(width) / double(height);
  const double sx = ((px / width) * 2 - 1) * f * aspect;
  const double sy = (1 - (py / height) * 2) * f;
  return (forward() + sx * right() + sy * trueUp()).normalized();
}

Status Camera::validate() const {
  if (!(eye - target).allFinite() || (eye - target).norm() == 0)
    return Status::badInput("camera: eye and target must differ");
  if (forward().cross(up).norm() < 1e-9) return Status::badInput("camera: up is parallel to the view direction");
  if (!(fovDeg > 0.1 && fovDeg < 179)) return Status::badInput("camera: --fov must be between 0.1 and 179 degrees");
  if (width < 1 || height < 1 || width > 16384 || height > 16384)
    return Status::badInput("camera: --size must be between 1x1 and 16384x16384");
  return Status::ok();
}

std::vector<Camera> orbitCameras(const Eigen::Vector3d& bmin, const Eigen::Vector3d& bmax, int count,
                                 const Eigen::Vector3d& upIn, double fovDeg, int width, int height) {
  const Eigen::Vector3d c = (bmin + bmax) / 2;
  // A box of zero size (one point, duplicates) still gets a camera that differs from its
  // target in double precision, also at georeferenced coordinates.
  const double r = std::max({(bmax - bmin).norm() / 2, 1e-12, 1e-9 * c.cwiseAbs().maxCoeff()});
  const double halfFov = std::min(fovDeg, fovDeg * width / double(height)) * M_PI / 360.0;
  const double dist = r / std::sin(halfFov) * 1.02;
  const Eigen::Vector3d up = upIn.normalized();
  const Eigen::Vector3d a = (std::abs(up.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitZ()).cross(up).normalized();
  const Eigen::Vector3d b = up.cross(a);
  const double elev = 20 * M_PI / 180;
  std::vector<Camera> cams;
  for (int i = 0; i < count; ++i) {
    const double th = 2 * M_PI * i / count;
    Camera cam;
    cam.target = c;
    cam.eye = c + dist * (std::cos(elev) * (std::cos(th) * b + std::sin(th) * a) + std::sin(elev) * up);
    cam.up = up;
    cam.fovDeg = fovDeg;
    cam.width = width;
    cam.height = height;
    cams.push_back(cam);
  }
  return cams;
}

}  // namespace sa
