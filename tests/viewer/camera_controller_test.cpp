#include "viewer/camera_controller.h"

#include <gtest/gtest.h>

namespace sa {
namespace {

Camera baseCamera(const Eigen::Vector3d& off) {
  Camera c;
  c.eye = off + Eigen::Vector3d(1, 2, 5);
  c.target = off + Eigen::Vector3d(0.2, 0.1, 0);
  c.width = 800;
  c.height = 600;
  return c;
}

TEST(CameraController, OrbitKeepsDistanceToPivotAndPivotOnScreen) {
  for (const Eigen::Vector3d& off : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(5e5, 5e6, 1e2)}) {
    CameraController cc(baseCamera(off));
    const Eigen::Vector3d pivot = cc.camera().target;
    const double d0 = (cc.camera().eye - pivot).norm();
    double px0, py0;
    ASSERT_TRUE(cc.project(pivot, px0, py0));
    for (int i = 0; i < 50; ++i) cc.orbit(pivot, 13.0, -7.0);
    EXPECT_NEAR((cc.camera().eye - pivot).norm(), d0, 1e-9 * (1 + off.norm()));
    double px, py;
    ASSERT_TRUE(cc.project(pivot, px, py));
    EXPECT_NEAR(px, px0, 1e-6);
    EXPECT_NEAR(py, py0, 1e-6);
    // Tilting far past the pole stops short of it: up never becomes parallel to the view.
    cc.orbit(pivot, 0, 100000);
    EXPECT_GT(cc.camera().forward().cross(cc.camera().up).norm(), 0.01);
  }
}

TEST(CameraController, ZoomToCursorKeepsThePointUnderTheCursor) {
  for (const Eigen::Vector3d& off : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(5e5, 5e6, 1e2)}) {
    CameraController cc(baseCamera(off));
    const double px = 613.25, py = 97.5, depth = 3.7;
    const Eigen::Vector3d p = cc.unproject(px, py, depth);
    for (double factor : {0.5, 0.8, 1.5}) {
      cc.zoomToCursor(px, py, (p - cc.camera().eye).dot(cc.camera().forward()), factor);
      double qx, qy;
      ASSERT_TRUE(cc.project(p, qx, qy));
      EXPECT_NEAR(qx, px, 1e-6);
      EXPECT_NEAR(qy, py, 1e-6);
    }
    EXPECT_LT((p - cc.camera().eye).norm(), (p - baseCamera(off).eye).norm());
  }
}

TEST(CameraController, PanMovesTheSceneWithTheCursor) {
  CameraController cc(baseCamera(Eigen::Vector3d(5e5, 5e6, 1e2)));
  const double depth = 4.0;
  const Eigen::Vector3d p = cc.unproject(400, 300, depth);
  const Eigen::Vector3d f0 = cc.camera().forward();
  cc.pan(40, -25, depth);
  double qx, qy;
  ASSERT_TRUE(cc.project(p, qx, qy));
  EXPECT_NEAR(qx, 440, 1e-6);
  EXPECT_NEAR(qy, 275, 1e-6);
  EXPECT_NEAR((cc.camera().forward() - f0).norm(), 0, 1e-12);  // orientation unchanged
}

TEST(CameraController, FrameAllAndPresetsSeeTheWholeBox) {
  CameraController cc(baseCamera(Eigen::Vector3d::Zero()));
  const Eigen::Vector3d lo(-1, -2, -0.5), hi(3, 1, 0.5);
  for (auto p : {CameraController::Preset::kTop, CameraController::Preset::kFront, CameraController::Preset::kSide}) {
    cc.preset(p, lo, hi);
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3d corner(k & 1 ? hi.x() : lo.x(), k & 2 ? hi.y() : lo.y(), k & 4 ? hi.z() : lo.z());
      double px, py;
      ASSERT_TRUE(cc.project(corner, px, py));
      EXPECT_GE(px, 0);
      EXPECT_LE(px, 800);
      EXPECT_GE(py, 0);
      EXPECT_LE(py, 600);
    }
  }
  // Fly moves without turning.
  const Eigen::Vector3d f0 = cc.camera().forward(), e0 = cc.camera().eye;
  cc.fly(1, 0, 0);
  EXPECT_NEAR((cc.camera().eye - e0 - f0).norm(), 0, 1e-12);
}

}  // namespace
}  // namespace sa
