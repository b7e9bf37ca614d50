#include "atlas/raycast.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/ray_box.h"

namespace sa {

CpuRaycaster::CpuRaycaster(const PackReader& pack) : pack_(pack), pyramids_(exact::buildPyramids(pack)) {
  for (const CellRecord& c : pack.cells()) {
    const Eigen::Vector3d O(c.origin), U(c.u), V(c.v), W(c.w);
    const double cu = (c.box[0] + c.box[1]) / 2, cv = (c.box[2] + c.box[3]) / 2, cw = (c.box[4] + c.box[5]) / 2;
    centers_.push_back(O + U * cu + V * cv + W * cw);
    radii_.push_back(0.5 * std::sqrt(std::pow(c.box[1] - c.box[0], 2) + std::pow(c.box[3] - c.box[2], 2) +
                                     std::pow(c.box[5] - c.box[4], 2)));
  }
}

double CpuRaycaster::texelHeight(const CellRecord& c, int i, int j) const {
  i = std::clamp(i, -1, int(c.tileW));
  j = std::clamp(j, -1, int(c.tileH));
  const uint16_t k = pack_.texel(c, i, j);
  if (k == 0) return std::numeric_limits<double>::quiet_NaN();
  return decodeHeight(k, c.box[4], c.box[5]);
}

double CpuRaycaster::height(const CellRecord& c, double u, double v) const {
  const double fx = std::clamp((u - c.box[0]) / (c.box[1] - c.box[0]) * c.tileW - 0.5, -0.5, c.tileW - 0.5);
  const double fy = std::clamp((v - c.box[2]) / (c.box[3] - c.box[2]) * c.tileH - 0.5, -0.5, c.tileH - 0.5);
  const int i0 = int(std::floor(fx)), j0 = int(std::floor(fy));
  const double ax = fx - i0, ay = fy - j0;
  double h[4] = {texelHeight(c, i0, j0), texelHeight(c, i0 + 1, j0), texelHeight(c, i0, j0 + 1), texelHeight(c, i0 + 1, j0 + 1)};
  if (std::isnan(h[0]) || std::isnan(h[1]) || std::isnan(h[2]) || std::isnan(h[3])) {
    // As the shader's sampleHeight: the nearest texel decides coverage; uncovered neighbours
    // take its tangent plane (stored normal), so a coverage edge is not a flat step.
    const int ni = std::clamp(int(std::floor(fx + 0.5)), 0, int(c.tileW) - 1);
    const int nj = std::clamp(int(std::floor(fy + 0.5)), 0, int(c.tileH) - 1);
    const double hn = texelHeight(c, ni, nj);
    if (std::isnan(hn) || !pack_.hasNormals()) return hn;
    double w[3];
    decodeNormal(pack_.normalTexel(c, ni, nj), w);  // world: into the cell's frame
    const double n[3] = {w[0] * c.u[0] + w[1] * c.u[1] + w[2] * c.u[2], w[0] * c.v[0] + w[1] * c.v[1] + w[2] * c.v[2],
                         w[0] * c.w[0] + w[1] * c.w[1] + w[2] * c.w[2]};
    const double gu = -n[0] / std::max(n[2], 0.05), gv = -n[1] / std::max(n[2], 0.05);
    const double tu = (c.box[1] - c.box[0]) / c.tileW, tv = (c.box[3] - c.box[2]) / c.tileH;
    for (int k = 0; k < 4; ++k)
      if (std::isnan(h[k])) h[k] = hn + gu * (i0 + (k & 1) - ni) * tu + gv * (j0 + (k >> 1) - nj) * tv;
  }
  return (h[0] * (1 - ax) + h[1] * ax) * (1 - ay) + (h[2] * (1 - ax) + h[3] * ax) * ay;
}

RayHit CpuRaycaster::cast(const Eigen::Vector3d& ro, const Eigen::Vector3d& rd) const { return cast(ro, rd, nullptr); }

RayHit CpuRaycaster::cast(const Eigen::Vector3d& ro, const Eigen::Vector3d& rd, exact::TraceStats* stats) const {
  RayHit best;
  best.t = std::numeric_limits<double>::infinity();
  auto cells = pack_.cells();
  for (uint32_t ci = 0; ci < cells.size(); ++ci) {
    // Bounding-sphere rejection.
    const Eigen::Vector3d oc = centers_[ci] - ro;
    const double tc = oc.dot(rd);
    if ((oc - rd * tc).squaredNorm() > radii_[ci] * radii_[ci]) continue;
    if (tc + radii_[ci] < 0 || tc - radii_[ci] > best.t) continue;
    const CellRecord& c = cells[ci];
    const Eigen::Vector3d U(c.u), V(c.v), W(c.w), rel = ro - Eigen::Vector3d(c.origin);
    const Eigen::Vector3d o(rel.dot(U), rel.dot(V), rel.dot(W)), d(rd.dot(U), rd.dot(V), rd.dot(W));
    double t0 = 0, t1 = best.t;
    if (!clipRayToBox(Eigen::Vector3d(c.box[0], c.box[2], c.box[4]), Eigen::Vector3d(c.box[1], c.box[3], c.box[5]), o, d, t0, t1))
      continue;
    double t;
    if (exact::traceCell(pack_, c, pyramids_.codes.data() + pyramids_.offsets[ci], o, d, t0, t1, t, stats) &&
        t < best.t) {
      best.hit = true;
      best.t = t;
      best.cell = ci;
    }
  }
  return best;
}

}  // namespace sa
