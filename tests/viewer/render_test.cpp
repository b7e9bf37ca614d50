// The GPU path against a double-precision CPU ray cast of the same pack, a camera inside a
// box, and georeferenced offsets.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "../common/render_util.h"
#include "atlas/raycast.h"
#include "preprocess/pipeline.h"
#include "viewer/camera_controller.h"
#include "viewer/egl_context.h"
#include "viewer/renderer.h"

namespace sa {
namespace {

class RenderTest : public test::GlTest {
 protected:

  std::string pack(const std::vector<Eigen::Vector3d>& pts, const std::vector<Eigen::Vector3d>& nrm,
                   const std::string& name, PackOptions opt = {}) {
    return test::packPoints(dir_, pts, nrm, name, opt);
  }
  static std::vector<float> cpuDepth(const PackReader& p, const Camera& cam) { return test::cpuDepth(p, cam); }

  test::TempDir dir_;
};

using test::Agreement;
using test::agreement;

// Stated tolerance: 0.1% of the bounding-box diagonal, on >= 99% of the pixels either
// render covers.
TEST_F(RenderTest, GpuMatchesCpuRayCast) {
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(30000, 1.0, Eigen::Vector3d::Zero(), pts, nrm);
  PackReader p;
  ASSERT_TRUE(p.open(pack(pts, nrm, "sphere")).isOk());
  Renderer r;
  ASSERT_TRUE(r.init(p).isOk());
  const double diag = Eigen::Vector3d(2, 2, 2).norm();
  for (const Eigen::Vector3d& eye : {Eigen::Vector3d(0.4, 1.1, 3.2), Eigen::Vector3d(-2.5, -0.3, 1.2)}) {
    Camera cam;
    cam.eye = eye;
    cam.target = Eigen::Vector3d(0.05, -0.02, 0.01);
    cam.width = cam.height = 96;
    cam.fovDeg = 50;
    FrameResult fr;
    ASSERT_TRUE(r.render(cam, RenderSettings{}, fr, true).isOk());
    const auto ref = cpuDepth(p, cam);
    const Agreement a = agreement(fr.depth, ref, 1e-3 * diag);
    std::printf("GPU vs CPU ray cast: %zu of %zu covered pixels agree within 0.1%% of the diagonal (max diff %.3g)\n",
                a.agree, a.covered, a.maxErr);
    ASSERT_GT(a.covered, 2000u);
    EXPECT_GE(double(a.agree), 0.99 * double(a.covered));
  }
}

// A camera inside a cell's box still sees the height field (the box's back faces are drawn
// and the ray's entry point is computed analytically).
TEST_F(RenderTest, CameraInsideABoxSeesTheSurface) {
  std::vector<Eigen::Vector3d> pts, nrm;
  for (int j = 0; j < 300; ++j)
    for (int i = 0; i < 300; ++i) {
      const double x = -1 + i / 150.0, y = -1 + j / 150.0;
      const double z = 0.1 * std::sin(4 * x) * std::cos(3 * y);
      pts.emplace_back(x, y, z);
      nrm.push_back(Eigen::Vector3d(-0.4 * std::cos(4 * x) * std::cos(3 * y), 0.3 * std::sin(4 * x) * std::sin(3 * y), 1).normalized());
    }
  PackReader p;
  ASSERT_TRUE(p.open(pack(pts, nrm, "bumps")).isOk());
  ASSERT_EQ(p.cells().size(), 1u);
  const CellRecord& c = p.cells()[0];
  Renderer r;
  ASSERT_TRUE(r.init(p).isOk());
  Camera cam;
  // Inside the box: between the surface (|z| <= 0.1) and the box top, near a trough.
  const Eigen::Vector3d origin(p.meta().origin);
  cam.eye = Eigen::Vector3d(-0.4, 0.0, 0.0) + origin * 0;
  cam.eye.z() = 0.08;
  cam.target = cam.eye + Eigen::Vector3d(1, 0.2, -0.4);
  cam.up = Eigen::Vector3d::UnitZ();
  cam.width = cam.height = 64;
  // The camera really is inside the box.
  const Eigen::Vector3d rel = cam.eye - origin - Eigen::Vector3d(c.origin);
  const double w = rel.dot(Eigen::Vector3d(c.w));
  ASSERT_GT(w, c.box[4]);
  ASSERT_LT(w, c.box[5]);
  FrameResult fr;
  ASSERT_TRUE(r.render(cam, RenderSettings{}, fr, true).isOk());
  const auto ref = cpuDepth(p, cam);
  const Agreement a = agreement(fr.depth, ref, 1e-3 * 3);
  std::printf("inside a box: %zu of %zu covered pixels agree\n", a.agree, a.covered);
  EXPECT_GT(a.covered, 64u * 64 / 3);
  EXPECT_GE(double(a.agree), 0.97 * double(a.covered));
}

// Camera-relative rendering: the same object at georeferenced coordinates renders the same
// depth image (difference <= 1e-4 of the diagonal) as at the origin.
TEST_F(RenderTest, GeoreferencedOffsetRendersTheSame) {
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(20000, 1.0, Eigen::Vector3d::Zero(), pts, nrm);
  const Eigen::Vector3d offset(5e5, 5e6, 1e2);
  std::vector<Eigen::Vector3d> moved = pts;
  for (auto& q : moved) q += offset;
  PackOptions opt;
  opt.texelSize = 0.01;
  PackReader a, b;
  ASSERT_TRUE(a.open(pack(pts, nrm, "near", opt)).isOk());
  ASSERT_TRUE(b.open(pack(moved, nrm, "far", opt)).isOk());
  Camera cam;
  cam.eye = Eigen::Vector3d(0.5, 1.0, 3.0);
  cam.target = Eigen::Vector3d::Zero();
  cam.width = cam.height = 96;
  Camera camFar = cam;
  camFar.eye += offset;
  camFar.target += offset;
  FrameResult fa, fb;
  {
    Renderer r;
    ASSERT_TRUE(r.init(a).isOk());
    ASSERT_TRUE(r.render(cam, RenderSettings{}, fa, true).isOk());
  }
  {
    Renderer r;
    ASSERT_TRUE(r.init(b).isOk());
    ASSERT_TRUE(r.render(camFar, RenderSettings{}, fb, true).isOk());
  }
  const double diag = Eigen::Vector3d(2, 2, 2).norm();
  size_t both = 0, differ = 0;
  double maxDiff = 0;
  for (size_t i = 0; i < fa.depth.size(); ++i) {
    const bool ha = std::isfinite(fa.depth[i]), hb = std::isfinite(fb.depth[i]);
    if (ha != hb) ++differ;
    if (ha && hb) {
      ++both;
      maxDiff = std::max(maxDiff, std::abs(double(fa.depth[i]) - fb.depth[i]));
    }
  }
  std::printf("offset (5e5, 5e6, 1e2): %zu pixels, coverage differs on %zu, max depth diff %.3g (%.2g of diagonal)\n",
              both, differ, maxDiff, maxDiff / diag);
  EXPECT_GT(both, 1000u);
  EXPECT_LE(differ, both / 200);
  EXPECT_LE(maxDiff, 1e-4 * diag);
}

// Clip box and section plane discard everything outside; shading modes change the image,
// not the geometry; eye-dome lighting only darkens.
TEST_F(RenderTest, ClipSectionAndShadingModes) {
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(30000, 1.0, Eigen::Vector3d(100, 200, 300), pts, nrm);
  PackReader p;
  ASSERT_TRUE(p.open(pack(pts, nrm, "clip")).isOk());
  Renderer r;
  ASSERT_TRUE(r.init(p).isOk());
  CameraController cc;
  Camera cam;
  cam.eye = Eigen::Vector3d(100.3, 200.8, 303.4);
  cam.target = Eigen::Vector3d(100, 200, 300);
  cam.width = cam.height = 96;
  FrameResult full, boxed, cut, edl, normals;
  ASSERT_TRUE(r.render(cam, RenderSettings{}, full, true).isOk());
  RenderSettings box;
  box.clip.box = true;
  box.clip.lo = Eigen::Vector3d(99, 199, 299);
  box.clip.hi = Eigen::Vector3d(101, 200, 301);  // the lower half in y
  ASSERT_TRUE(r.render(cam, box, boxed, true).isOk());
  RenderSettings sec;
  sec.clip.plane = true;
  sec.clip.point = Eigen::Vector3d(100.2, 200, 300);
  sec.clip.normal = Eigen::Vector3d(-1, 0, 0);  // keep x <= 100.2
  ASSERT_TRUE(r.render(cam, sec, cut, true).isOk());
  cc = CameraController(cam);
  size_t nFull = 0, nBox = 0, nCut = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const size_t i = size_t(y) * cam.width + x;
      nFull += std::isfinite(full.depth[i]);
      if (std::isfinite(boxed.depth[i])) {
        ++nBox;
        const Eigen::Vector3d w = cc.unproject(x + 0.5, y + 0.5, boxed.depth[i]);
        EXPECT_LE(w.y(), 200.0 + 1e-3);
      }
      if (std::isfinite(cut.depth[i])) {
        ++nCut;
        const Eigen::Vector3d w = cc.unproject(x + 0.5, y + 0.5, cut.depth[i]);
        EXPECT_LE(w.x(), 100.2 + 1e-3);
      }
    }
  EXPECT_GT(nBox, nFull / 4);
  EXPECT_LT(nBox, nFull * 3 / 4);
  EXPECT_GT(nCut, nFull / 4);
  EXPECT_LT(nCut, nFull);
  RenderSettings e;
  e.edl = true;
  ASSERT_TRUE(r.render(cam, e, edl, true).isOk());
  RenderSettings n;
  n.shading = Shading::kNormals;
  ASSERT_TRUE(r.render(cam, n, normals, true).isOk());
  size_t darker = 0, brighter = 0, colourful = 0;
  for (size_t i = 0; i < full.depth.size(); ++i) {
    if (!std::isfinite(full.depth[i])) continue;
    EXPECT_EQ(edl.depth[i], full.depth[i]);
    EXPECT_EQ(normals.depth[i], full.depth[i]);
    const int a = full.color.rgba[4 * i], b = edl.color.rgba[4 * i];
    darker += b < a;
    brighter += b > a + 1;
    const uint8_t* c = &normals.color.rgba[4 * i];
    colourful += std::max({c[0], c[1], c[2]}) - std::min({c[0], c[1], c[2]}) > 40;
  }
  EXPECT_EQ(brighter, 0u);
  EXPECT_GT(darker, 0u);
  EXPECT_GT(colourful, nFull / 2);
}

// Scan colours travel from the PLY through pull-push into the colour pages and the image.
TEST_F(RenderTest, ScanColoursReachTheImage) {
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(20000, 1.0, Eigen::Vector3d::Zero(), pts, nrm);
  std::string ply = "ply\nformat ascii 1.0\nelement vertex " + std::to_string(pts.size()) +
                    "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\n"
                    "property float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
  for (size_t i = 0; i < pts.size(); ++i) {
    const bool top = pts[i].y() > 0;
    ply += std::to_string(pts[i].x()) + " " + std::to_string(pts[i].y()) + " " + std::to_string(pts[i].z()) + " " +
           std::to_string(nrm[i].x()) + " " + std::to_string(nrm[i].y()) + " " + std::to_string(nrm[i].z()) +
           (top ? " 230 40 30\n" : " 30 40 230\n");
  }
  test::writeText(dir_.file("c.ply"), ply);
  auto in = InputSet::open({dir_.file("c.ply")});
  ASSERT_TRUE(in.isOk());
  PackSummary sum;
  ASSERT_TRUE(packInput(*in, dir_.file("c.hfa"), PackOptions{}, nullptr, sum).isOk());
  EXPECT_TRUE(sum.hasColor);
  PackReader p;
  ASSERT_TRUE(p.open(dir_.file("c.hfa")).isOk());
  ASSERT_TRUE(p.hasColor());
  Renderer r;
  ASSERT_TRUE(r.init(p).isOk());
  Camera cam;
  cam.eye = Eigen::Vector3d(0, 3.5, 0.01);  // from above: the red hemisphere
  cam.target = Eigen::Vector3d::Zero();
  cam.width = cam.height = 64;
  FrameResult fr;
  ASSERT_TRUE(r.render(cam, RenderSettings{}, fr, false).isOk());
  size_t red = 0, blue = 0;
  for (size_t i = 0; i < fr.color.rgba.size(); i += 4) {
    const int R = fr.color.rgba[i], B = fr.color.rgba[i + 2];
    red += R > 2 * B && R > 60;
    blue += B > 2 * R && B > 60;
  }
  EXPECT_GT(red, 64u * 64 / 4);
  EXPECT_EQ(blue, 0u);
  RenderSettings plain;
  plain.useColor = false;
  ASSERT_TRUE(r.render(cam, plain, fr, false).isOk());
  red = 0;
  for (size_t i = 0; i < fr.color.rgba.size(); i += 4) red += fr.color.rgba[i] > 2 * fr.color.rgba[i + 2];
  EXPECT_EQ(red, 0u);  // --no-color: the plain base colour
}

}  // namespace
}  // namespace sa
