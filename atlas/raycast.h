// Reference ray caster on the CPU, in double precision: the same height fields, the same
// sampling rule (bilinear; the nearest texel where a neighbour is uncovered) and the same
// one-sided surface, covered only where the tile says so (no hit through the side of a sheet), as
// the GPU shader, but marched at a quarter texel and bisected to convergence. Used to check the GPU render and for picking.
#pragma once
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "atlas/pack_file.h"

namespace sa {

struct RayHit {
  bool hit = false;
  double t = 0;           // distance along the (unit) direction
  uint32_t cell = 0;
};

class CpuRaycaster {
 public:
  explicit CpuRaycaster(const PackReader& pack);
  // o: ray origin relative to the pack origin; d: unit direction.
  RayHit cast(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const;
  // Height at frame point (u, v) of cell c, or NaN where uncovered.
  double height(const CellRecord& c, double u, double v) const;

 private:
  double texelHeight(const CellRecord& c, int i, int j) const;
  // Marches cell c's height field along o + t d (frame coordinates) over [t0, t1].
  bool march(const CellRecord& c, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t0, double t1, double dt,
             double& tHit) const;
  const PackReader& pack_;
  std::vector<Eigen::Vector3d> centers_;
  std::vector<double> radii_;
};

}  // namespace sa
