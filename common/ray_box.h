// The span of a ray inside an axis-aligned box: the slab test every CPU caster and its tests use.
#pragma once
#include <algorithm>
#include <cmath>
#include <utility>

#include <Eigen/Core>

namespace sa {

// Narrows [t0, t1] to where o + t d lies inside [lo, hi] (each axis); false when nothing is left.
// An axis the ray runs parallel to keeps the span only when o lies within the box along it.
inline bool clipRayToBox(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Eigen::Vector3d& o,
                         const Eigen::Vector3d& d, double& t0, double& t1) {
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-300) {
      if (o[a] < lo[a] || o[a] > hi[a]) return false;
      continue;
    }
    double ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return t0 < t1;
}

}  // namespace sa
