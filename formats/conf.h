// Stanford scan-set (.conf) files: one `bmesh <file> tx ty tz q0 q1 q2 q3` line per range
// scan; the aligned point is p' = R(q)^T p + t with R(q) the Hamilton rotation of the unit
// quaternion (x=q0, y=q1, z=q2, w=q3) (verified against the reconstructions, see
// ../shared/data/PROVENANCE.md). `camera` and `mesh` lines are ignored.
#pragma once
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/error.h"

namespace sa {

struct ScanEntry {
  std::string path;            // resolved relative to the .conf file
  Eigen::Matrix3d rotation;    // R(q)^T: applied to scan-space points
  Eigen::Vector3d translation;
  // Direction from the scanned surface toward the scanner, in aligned coordinates. In a
  // Cyberware range image the scanner looks along -z of the scan's own frame, so this is
  // R(q)^T * (0,0,1). (The scan-space origin is not the scanner: for the bunny it lies
  // 10 cm from the scanned surface, inside the scanned volume.)
  Eigen::Vector3d towardScanner;
};

Result<std::vector<ScanEntry>> readConf(const std::string& path);

}  // namespace sa
