#include "viewer/culling.h"

#include <algorithm>
#include <cmath>

namespace sa {

CellCuller::CellCuller(std::span<const CellRecord> cells) {
  bounds_.reserve(cells.size());
  for (const CellRecord& c : cells) {
    Bounds b;
    b.origin = Eigen::Vector3d(c.origin);
    b.u = Eigen::Vector3d(c.u);
    b.v = Eigen::Vector3d(c.v);
    b.w = Eigen::Vector3d(c.w);
    std::copy(c.box, c.box + 6, b.box);
    const double cu = (c.box[0] + c.box[1]) / 2, cv = (c.box[2] + c.box[3]) / 2, cw = (c.box[4] + c.box[5]) / 2;
    b.center = b.origin + b.u * cu + b.v * cv + b.w * cw;
    b.radius = 0.5 * std::sqrt(std::pow(c.box[1] - c.box[0], 2) + std::pow(c.box[3] - c.box[2], 2) +
                               std::pow(c.box[5] - c.box[4], 2));
    bounds_.push_back(b);
  }
}

void CellCuller::compute(const Camera& cam, const Eigen::Vector3d& eye, double nearPlane, const CullOptions& opt,
                         VisibleSet& out) const {
  out.front.clear();
  out.inside.clear();
  out.splats.clear();
  out.sliced.clear();
  out.missing.clear();
  out.submitted = static_cast<uint32_t>(bounds_.size());
  out.culled = 0;
  const Eigen::Vector3d f = cam.forward(), r = cam.right(), u = cam.trueUp();
  const double ty = std::tan(cam.fovDeg * M_PI / 360.0), tx = ty * cam.width / double(cam.height);
  const double nx = std::sqrt(1 + tx * tx), ny = std::sqrt(1 + ty * ty);
  const double focalPx = cam.height / (2 * ty);
  std::vector<double> depthOf(opt.frontToBack ? bounds_.size() : 0);
  for (uint32_t i = 0; i < bounds_.size(); ++i) {
    const Bounds& b = bounds_[i];
    if (opt.clipBox) {
      const Eigen::Vector3d nearest = b.center.cwiseMax(opt.clipLo).cwiseMin(opt.clipHi);
      if ((nearest - b.center).norm() > b.radius) {
        ++out.culled;
        continue;
      }
    }
    if (opt.clipPlane && (b.center - opt.planePoint).dot(opt.planeNormal) < -b.radius) {
      ++out.culled;
      continue;
    }
    const Eigen::Vector3d c = b.center - eye;
    const double z = c.dot(f), x = c.dot(r), y = c.dot(u);
    if (opt.frustum) {
      const bool outside = z < -b.radius || (x - z * tx) / nx > b.radius || (-x - z * tx) / nx > b.radius ||
                           (y - z * ty) / ny > b.radius || (-y - z * ty) / ny > b.radius;
      if (outside) {
        ++out.culled;
        continue;
      }
    }
    // Camera in the cell's frame: inside the box (with a margin of the near plane, so a
    // front face clipped by the near plane is never relied on)?
    const Eigen::Vector3d rel = eye - b.origin;
    const double o[3] = {rel.dot(b.u), rel.dot(b.v), rel.dot(b.w)};
    const double margin = 2 * nearPlane + 1e-9 * b.radius;
    bool inside = true;
    for (int a = 0; a < 3; ++a) inside = inside && o[a] > b.box[2 * a] - margin && o[a] < b.box[2 * a + 1] + margin;
    const double dist = std::max(z, b.radius * 1e-3);
    const double px = 2 * b.radius * focalPx / dist;  // projected diameter in pixels
    DrawItem item{i, static_cast<uint32_t>(opt.maxSteps)};
    if (opt.adaptiveSteps) {
      // Fewer steps for small or face-on boxes, more at grazing angles: a step of about
      // 16 pixels face-on, shrinking with 1/cos of the angle between the ray and W.
      const double cosv = std::abs(c.normalized().dot(b.w));
      const double want = px / 16.0 / std::max(cosv, 0.25);
      item.steps = static_cast<uint32_t>(std::clamp(std::ceil(want), double(opt.minSteps), double(opt.maxSteps)));
    }
    if (opt.frontToBack) depthOf[i] = z;
    if (opt.cellResident && !opt.cellResident[i]) {
      out.missing.push_back(i);
      ++out.culled;
    } else if (!inside && opt.subpixelSplats && px < opt.splatPixels) {
      out.splats.push_back(item);
    } else if (!inside && px < opt.slicePixels) {
      out.sliced.push_back(item);
    } else if (inside || !opt.backfaceCull) {
      out.inside.push_back(item);
    } else {
      out.front.push_back(item);
    }
  }
  if (opt.frontToBack) {
    auto byDepth = [&](const DrawItem& a, const DrawItem& b) { return depthOf[a.cell] < depthOf[b.cell]; };
    std::sort(out.front.begin(), out.front.end(), byDepth);
    std::sort(out.inside.begin(), out.inside.end(), byDepth);
    std::sort(out.sliced.begin(), out.sliced.end(), byDepth);
    std::sort(out.missing.begin(), out.missing.end(), [&](uint32_t a, uint32_t b) { return depthOf[a] < depthOf[b]; });
  }
}

}  // namespace sa
