// Reference ray caster on the CPU, in double precision: the same height fields, the same
// sampling rule (bilinear; the nearest texel where a neighbour is uncovered) and the same
// one-sided surface, covered only where the tile says so (no hit through the side of a sheet), as
// the GPU shader, traced exactly: the `exact` mode's maximum-mipmap traversal with the
// ray-patch root in closed form (modes/exact/exact.h). The reference every mode is judged
// against, and picking.
#pragma once
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "atlas/pack_file.h"
#include "modes/exact/exact.h"

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
  // As cast, also counting the pyramid nodes visited (summed over the cells tried).
  RayHit cast(const Eigen::Vector3d& o, const Eigen::Vector3d& d, exact::TraceStats* stats) const;
  // Height at frame point (u, v) of cell c, or NaN where uncovered.
  double height(const CellRecord& c, double u, double v) const;

 private:
  double texelHeight(const CellRecord& c, int i, int j) const;
  const PackReader& pack_;
  std::vector<Eigen::Vector3d> centers_;
  std::vector<double> radii_;
  exact::Pyramids pyramids_;
};

}  // namespace sa
