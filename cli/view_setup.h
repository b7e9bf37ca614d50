// Camera options shared by render, bench and eval: --path, --orbit, --eye/--target/--up/--fov,
// --size.
#pragma once
#include <string>
#include <vector>

#include "atlas/pack_file.h"
#include "cli/args.h"
#include "viewer/camera.h"
#include "viewer/renderer.h"

namespace sa {

// defaultOrbit: views when neither --path nor --eye is given (0: one default view).
Status camerasFromArgs(const Args& a, const PackReader& pack, int defaultOrbit, int defaultSize,
                       std::vector<Camera>& out);
std::vector<std::string> splitList(const std::string& s);
// --mode LIST (default parallax) and --iterations LIST (default kDefaultIterations), as bench and eval take them.
Status modesAndIterations(const Args& a, std::vector<RenderMode>& modes, std::vector<int>& iterations);
// --slices N|auto (the slices mode's quads per cell; auto: 0) into rs.slices when given.
Status slicesFromArgs(const Args& a, RenderSettings& rs);
// --opt with exactly `count` comma-separated numbers.
Status numberList(const Args& a, const std::string& opt, size_t count, std::vector<double>& out);
void packBounds(const PackReader& pack, Eigen::Vector3d& lo, Eigen::Vector3d& hi);
// Says on stderr when the pack lacks what mode m needs (and what draws instead, and how to bake it).
void warnIfModeFallsBack(const Renderer& r, const PackReader& pack, RenderMode m);

}  // namespace sa
