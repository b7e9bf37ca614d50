// Groove detection in one planar region (grooves/plane.cpp): points as (u, v, height) over a
// frame, lines in the same coordinates. detect.cpp splits a scan into such regions.
#pragma once
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "grooves/grooves.h"

namespace sa::grooves {

struct PlaneLine {
  std::vector<Eigen::Vector3d> uvh;  // centre line at the rim's height (the robust low-pass)
  double width = 0, depth = 0, confidence = 0;
  std::string shape = "V";
  std::vector<std::pair<float, float>> profile;
};

struct PlaneResult {
  std::vector<PlaneLine> lines;
  double noise = 0;  // robust std of the points' residual
};

// How strongly the points' residual leans below the surface (grooves) rather than above, times
// the point count: positive when the frame's normal points out of the grooved side.
double sideEvidence(const std::vector<Eigen::Vector3d>& uvh, double spacing, const GrooveOptions& opt);

// Width, depth, shape and profile of a given line (plane coordinates) from the points across it;
// false when too few points lie beside it.
bool measureInPlane(const std::vector<Eigen::Vector3d>& uvh, const std::vector<Eigen::Vector2d>& line, double spacing,
                    const GrooveOptions& opt, PlaneLine& out, double& noise);

PlaneResult detectInPlane(const std::vector<Eigen::Vector3d>& uvh, double spacing, const GrooveOptions& opt);

}  // namespace sa::grooves
