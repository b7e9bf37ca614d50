#include "preprocess/up_axis.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "atlas/pack_format.h"

namespace sa {
namespace {

// A flat area holding this share of all cells' area, facing along a coordinate axis, is ground.
constexpr double kGroundShare = 0.3;

}  // namespace

Eigen::Vector3d dominantFlatNormal(const std::vector<UpCell>& cells, const Eigen::Vector3d& near, double maxAngleDeg,
                                   double minShare, double* share) {
  const double cosNear = std::cos(maxAngleDeg * M_PI / 180), cosGroup = std::cos(15 * M_PI / 180);
  std::vector<UpCell> cand;
  double total = 0;
  for (const UpCell& c : cells) {
    total += c.area;
    const Eigen::Vector3d w = c.w.dot(near) < 0 ? Eigen::Vector3d(-c.w) : c.w;
    if (w.dot(near) >= cosNear) cand.push_back({w, c.area});
  }
  if (cand.empty() || !(total > 0)) return Eigen::Vector3d::Zero();
  // Seeds: the largest cells; each gathers the cells within 15° of it.
  std::vector<size_t> order(cand.size());
  std::iota(order.begin(), order.end(), size_t(0));
  const size_t seeds = std::min<size_t>(64, order.size());
  std::partial_sort(order.begin(), order.begin() + long(seeds), order.end(),
                    [&](size_t a, size_t b) { return cand[a].area > cand[b].area; });
  double bestArea = 0;
  Eigen::Vector3d best = Eigen::Vector3d::Zero();
  for (size_t s = 0; s < seeds; ++s) {
    const Eigen::Vector3d seed = cand[order[s]].w;
    double area = 0;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const UpCell& c : cand)
      if (c.w.dot(seed) >= cosGroup) {
        area += c.area;
        sum += c.area * c.w;
      }
    if (area > bestArea) {
      bestArea = area;
      best = sum.normalized();
    }
  }
  if (share) *share = bestArea / total;
  return bestArea >= minShare * total ? best : Eigen::Vector3d::Zero();
}

double HeightMoments::skew(int a) const {
  if (count < 3) return 0;
  const double m = sum[a] / count, m2 = sum2[a] / count - m * m;
  const double m3 = sum3[a] / count - 3 * m * sum2[a] / count + 2 * m * m * m;
  return m2 > 0 ? m3 / std::pow(m2, 1.5) : 0;
}

UpDecision decideUp(const InputSet& input, const Eigen::Vector3d& given, const Eigen::Vector3d& lo,
                    const Eigen::Vector3d& hi, const std::vector<UpCell>& cells, const HeightMoments& moments,
                    bool reliableNormals) {
  UpDecision d;
  if (given.norm() > 0) {
    d.up = given.normalized();
    d.source = kUpGiven;
    return d;
  }
  // A convention every file with one agrees on.
  Eigen::Vector3d strong = Eigen::Vector3d::Zero(), weak = Eigen::Vector3d::Zero();
  bool conflict = false, camera = false;
  for (const InputFile& f : input.files()) {
    if (f.up.norm() == 0) continue;
    Eigen::Vector3d& slot = f.upIsConvention ? strong : weak;
    if (slot.norm() == 0) slot = f.up;
    else if (f.upIsConvention && (slot - f.up).norm() > 1e-9) conflict = true;
    camera |= f.upIsConvention && f.upFromCamera;
  }
  if (strong.norm() > 0 && !conflict) {
    d.up = strong.normalized();
    d.source = kUpConvention;
    if (camera) {
      // A camera's -y is only roughly up: the largest flat area near it (floor, table) is.
      const Eigen::Vector3d flat = dominantFlatNormal(cells, d.up, 45, 0.1);
      if (flat.norm() > 0) {
        d.up = flat;
        d.source = kUpFromData;
      }
    }
    return d;
  }
  // Which way along coordinate axis a is up: the side most of the surface faces (reliable
  // normals; a closed surface faces every way alike, its area-weighted normals sum to zero),
  // else the side its heights skew to, else the format's usual default, else the axis as it points.
  double totalArea = 0;
  for (const UpCell& c : cells) totalArea += c.area;
  auto side = [&](int a) {
    if (reliableNormals) {
      double facing = 0;
      for (const UpCell& c : cells) facing += c.area * c.w[a];
      if (std::abs(facing) > 0.05 * totalArea) return facing < 0 ? -1.0 : 1.0;
    }
    if (std::abs(moments.skew(a)) > 0.1) return moments.skew(a) < 0 ? -1.0 : 1.0;
    if (std::abs(weak[a]) > 0.5) return weak[a] < 0 ? -1.0 : 1.0;
    return 1.0;
  };
  // Terrain-like extents (one side under a fifth of the next): the thin axis, on the side most
  // of the surface faces (reliable normals) or its heights skew to.
  const Eigen::Vector3d ext = hi - lo;
  int axes[3] = {0, 1, 2};
  std::sort(axes, axes + 3, [&](int a, int b) { return ext[a] < ext[b]; });
  if (ext[axes[0]] < 0.2 * ext[axes[1]]) {
    Eigen::Vector3d axis = Eigen::Vector3d::Unit(axes[0]);
    d.up = side(axes[0]) * axis;
    d.source = kUpFromData;
    return d;
  }
  // A large flat area facing along a coordinate axis (the ground of a terrestrial scan): that axis.
  double bestShare = 0;
  for (int a = 0; a < 3; ++a) {
    double share = 0;
    const Eigen::Vector3d axis = Eigen::Vector3d::Unit(a);
    const Eigen::Vector3d flat = dominantFlatNormal(cells, axis, 20, kGroundShare, &share);
    if (flat.norm() > 0 && share > bestShare) {
      bestShare = share;
      d.up = side(a) * axis;
      d.source = kUpFromData;
    }
  }
  if (bestShare > 0) return d;
  d.up = weak.norm() > 0 ? Eigen::Vector3d(weak.normalized()) : Eigen::Vector3d::UnitY();
  d.source = weak.norm() > 0 ? kUpConvention : kUpUnknown;
  return d;
}

}  // namespace sa
