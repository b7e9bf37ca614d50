#include "viewer/culling.h"

#include <gtest/gtest.h>

namespace sa {
namespace {

// A 5x5x5 grid of unit cells (axis-aligned frames) centred on the origin.
std::vector<CellRecord> grid() {
  std::vector<CellRecord> cells;
  for (int z = -2; z <= 2; ++z)
    for (int y = -2; y <= 2; ++y)
      for (int x = -2; x <= 2; ++x) {
        CellRecord c{};
        c.origin[0] = 4.0 * x;
        c.origin[1] = 4.0 * y;
        c.origin[2] = 4.0 * z;
        c.u[0] = c.v[1] = c.w[2] = 1;
        c.box[0] = c.box[2] = c.box[4] = -0.5;
        c.box[1] = c.box[3] = c.box[5] = 0.5;
        c.tileW = c.tileH = 8;
        cells.push_back(c);
      }
  return cells;
}

TEST(Culling, FrustumDropsBoxesBehindAndBesideTheCamera) {
  auto cells = grid();
  CellCuller culler(cells);
  Camera cam;
  cam.eye = Eigen::Vector3d(0, 0, 30);
  cam.target = Eigen::Vector3d(0, 0, 0);
  cam.fovDeg = 10;  // a narrow view: only the central column of cells
  VisibleSet vis;
  culler.compute(cam, cam.eye, 1e-4, CullOptions{}, vis);
  EXPECT_EQ(vis.submitted, 125u);
  EXPECT_EQ(vis.front.size() + vis.inside.size() + vis.splats.size(), 125u - vis.culled);
  EXPECT_GE(vis.culled, 100u);
  EXPECT_GE(vis.front.size(), 5u);  // the column along the view axis
  CullOptions off;
  off.frustum = false;
  culler.compute(cam, cam.eye, 1e-4, off, vis);
  EXPECT_EQ(vis.culled, 0u);
  // Looking away: everything culled.
  cam.target = Eigen::Vector3d(0, 0, 60);
  culler.compute(cam, cam.eye, 1e-4, CullOptions{}, vis);
  EXPECT_EQ(vis.culled, 125u);
}

TEST(Culling, CameraInsideABoxGetsItsBackFacesAndOrderIsFrontToBack) {
  auto cells = grid();
  CellCuller culler(cells);
  Camera cam;
  cam.eye = Eigen::Vector3d(0.1, 0.2, 0.3);  // inside the central cell
  cam.target = Eigen::Vector3d(0, 0, -20);
  VisibleSet vis;
  culler.compute(cam, cam.eye, 1e-4, CullOptions{}, vis);
  ASSERT_EQ(vis.inside.size(), 1u);
  EXPECT_EQ(vis.inside[0].cell, 62u);  // (0,0,0) in the 5x5x5 grid
  for (size_t i = 1; i < vis.front.size(); ++i) {
    const double a = cam.eye.z() - cells[vis.front[i - 1].cell].origin[2];
    const double b = cam.eye.z() - cells[vis.front[i].cell].origin[2];
    EXPECT_LE(a, b + 4.0 * std::sqrt(2.0)) << "not front to back";
  }
  CullOptions noBackface;
  noBackface.backfaceCull = false;
  culler.compute(cam, cam.eye, 1e-4, noBackface, vis);
  EXPECT_TRUE(vis.front.empty());
}

TEST(Culling, StepsFollowProjectedSizeWithinBoundsAndTinyBoxesSplat) {
  auto cells = grid();
  CellCuller culler(cells);
  Camera cam;
  cam.width = cam.height = 1024;
  cam.eye = Eigen::Vector3d(0, 0, 4);  // close to the top layer's central cell
  cam.target = Eigen::Vector3d(0, 0, 0);
  CullOptions opt;
  opt.maxSteps = 16;
  VisibleSet vis;
  culler.compute(cam, cam.eye, 1e-4, opt, vis);
  uint32_t lo = 1000, hi = 0;
  for (const auto* list : {&vis.front, &vis.inside})
    for (const DrawItem& d : *list) {
      lo = std::min(lo, d.steps);
      hi = std::max(hi, d.steps);
    }
  EXPECT_GE(lo, uint32_t(opt.minSteps));
  EXPECT_LE(hi, 16u);
  EXPECT_EQ(hi, 16u);  // the near box is large on screen
  EXPECT_LT(lo, hi);   // far boxes get fewer
  // From far away every box is under a pixel: all splats.
  cam.eye = Eigen::Vector3d(0, 0, 1e6);
  cam.width = cam.height = 64;
  culler.compute(cam, cam.eye, 1e-4, opt, vis);
  EXPECT_EQ(vis.splats.size(), 125u - vis.culled);
  opt.subpixelSplats = false;
  culler.compute(cam, cam.eye, 1e-4, opt, vis);
  EXPECT_TRUE(vis.splats.empty());
}

}  // namespace
}  // namespace sa
