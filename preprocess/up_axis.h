// The pack's up axis, decided once when packing and stored in the pack (docs/FORMAT.md), so
// every view (orbits, the window, the height ramp) stands the scan the right way up: given by
// the user, else the format's convention (LAS: +z; Stanford scan sets: +y; an organized PCD is
// a camera image: -y, refined to the normal of the largest flat area near it, the floor or the
// table), else from the data (terrain-like extents: the thin axis), else the format's usual
// default (PLY, OBJ, OFF, Draco, text: +y; STL: +z).
#pragma once
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "formats/source.h"

namespace sa {

struct UpCell {
  Eigen::Vector3d w;  // the cell's height axis (oriented with the surface normals)
  double area = 0;    // its extent over the plane
};

// Third moments of the points' coordinates about their mean, per axis: the skew of heights
// (trees, buildings and people stand up from the ground, not down), for the sign of a
// terrain's up axis when normals cannot tell (estimated normals of a plain cloud point away from
// its centroid, which for a sheet is either side).
struct HeightMoments {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero(), sum2 = Eigen::Vector3d::Zero(), sum3 = Eigen::Vector3d::Zero();
  double count = 0;
  void add(const Eigen::Vector3d& p) {
    sum += p;
    sum2 += p.cwiseProduct(p);
    sum3 += p.cwiseProduct(p).cwiseProduct(p);
    count += 1;
  }
  // Skewness along axis a (0 when undefined).
  double skew(int a) const;
};

struct UpDecision {
  Eigen::Vector3d up = Eigen::Vector3d::UnitY();
  uint32_t source = 0;  // UpSource
};

// reliableNormals: the cells' axes are oriented by the file's normals or a mesh's faces (else the
// sign of a terrain's up comes from the height skew).
UpDecision decideUp(const InputSet& input, const Eigen::Vector3d& given, const Eigen::Vector3d& boundsMin,
                    const Eigen::Vector3d& boundsMax, const std::vector<UpCell>& cells, const HeightMoments& moments,
                    bool reliableNormals);

// The area-weighted mean height axis of the largest group of cells whose axes lie within 15°
// of each other and within `maxAngleDeg` of `near` (axes turned to agree with `near`); zero
// when those cells hold less than `minShare` of all cells' area. share (may be null): their share.
Eigen::Vector3d dominantFlatNormal(const std::vector<UpCell>& cells, const Eigen::Vector3d& near, double maxAngleDeg,
                                   double minShare, double* share = nullptr);

}  // namespace sa
