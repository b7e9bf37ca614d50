#include "atlas/raycast.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace sa {

CpuRaycaster::CpuRaycaster(const PackReader& pack) : pack_(pack) {
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
  const double h00 = texelHeight(c, i0, j0), h10 = texelHeight(c, i0 + 1, j0);
  const double h01 = texelHeight(c, i0, j0 + 1), h11 = texelHeight(c, i0 + 1, j0 + 1);
  if (std::isnan(h00) || std::isnan(h10) || std::isnan(h01) || std::isnan(h11)) {
    const int ni = std::clamp(int(std::floor(fx + 0.5)), 0, int(c.tileW) - 1);
    const int nj = std::clamp(int(std::floor(fy + 0.5)), 0, int(c.tileH) - 1);
    return texelHeight(c, ni, nj);
  }
  return (h00 * (1 - ax) + h10 * ax) * (1 - ay) + (h01 * (1 - ax) + h11 * ax) * ay;
}

RayHit CpuRaycaster::cast(const Eigen::Vector3d& ro, const Eigen::Vector3d& rd) const {
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
    for (int a = 0; a < 3; ++a) {
      const double lo = c.box[2 * a], hi = c.box[2 * a + 1];
      if (std::abs(d[a]) < 1e-300) {
        if (o[a] < lo || o[a] > hi) { t0 = 1; t1 = 0; }
        continue;
      }
      double ta = (lo - o[a]) / d[a], tb = (hi - o[a]) / d[a];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    if (!(t0 < t1)) continue;
    const double texel = std::min((c.box[1] - c.box[0]) / c.tileW, (c.box[3] - c.box[2]) / c.tileH);
    const double horiz = std::max(1e-300, std::hypot(d.x(), d.y()));
    const double dt = std::min((t1 - t0) / 16, 0.25 * texel / horiz);
    auto g = [&](double t) {
      const Eigen::Vector3d p = o + d * t;
      const double h = height(c, p.x(), p.y());
      return std::isnan(h) ? std::numeric_limits<double>::infinity() : p.z() - h;  // uncovered: "above"
    };
    double tp = t0, gp = g(t0);
    for (double t = t0 + dt;; t += dt) {
      const bool last = t >= t1;
      if (last) t = t1;
      const double gt = g(t);
      if (gp > 0 && gt <= 0) {
        double lo = tp, hi = t;
        for (int k = 0; k < 60; ++k) {
          const double m = 0.5 * (lo + hi);
          (g(m) > 0 ? lo : hi) = m;
        }
        if (hi < best.t) {
          best.hit = true;
          best.t = hi;
          best.cell = ci;
        }
        break;
      }
      tp = t;
      gp = gt;
      if (last) break;
    }
  }
  return best;
}

}  // namespace sa
