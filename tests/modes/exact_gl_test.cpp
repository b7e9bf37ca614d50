// The exact mode on the GPU (modes/exact/exact.glsl) against its double-precision CPU traversal
// (the reference, CpuRaycaster) over the stress suite's cases: grazing views 60-89.9 degrees,
// rays along the box's faces and edges and through a corner, cameras on a face and inside the
// box, the tall spike, degenerate cells, and the bunny's raw scans. Counters come back from the
// shader: pyramid nodes per ray.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "../common/render_util.h"
#include "modes/registry.h"
#include "viewer/camera_path.h"
#include "viewer/renderer.h"

namespace sa {
namespace {

struct Totals {
  size_t covered = 0, agree = 0, coverageDiffers = 0;
  WorkCounters work;
};

class ExactGl : public test::GlTest {
 protected:
  void SetUp() override { totals_ = Totals{}; }
  // Over every view of the test: >= 99.9 % of covered pixels within 1e-4 of the diagonal of the
  // CPU reference, no ray stopped by the cap, and the work per ray within the p99 <= 64
  // (p90 <= 32). With the maxima alone, rays under the sheet (its underside, through holes)
  // solved every patch they crossed: p99 255 at 89 degrees and on the bunny's silhouettes; the
  // minima skip them (measured p99: grazing 52, faces 38, spike 25, bunny 40).
  void TearDown() override {
    const WorkCounters& w = totals_.work;
    std::printf("[exact-gl] test total: %zu covered pixels, %.4f%% within 1e-4 diag, nodes/ray p50 %u p90 %u p99 %u max %u, "
                "capped %llu\n", totals_.covered, totals_.covered ? 100.0 * double(totals_.agree) / double(totals_.covered) : 0.0,
                w.p50, w.p90, w.p99, w.max, (unsigned long long)w.capped);
    EXPECT_GE(double(totals_.agree), 0.999 * double(totals_.covered));
    EXPECT_EQ(w.capped, 0u);
    EXPECT_LE(w.p99, 64u);
    EXPECT_LE(w.p90, 32u);
  }

  // Bakes the exact mode into the pack, renders cam with it and compares with the CPU reference.
  test::Agreement run(const std::string& packPath, const Camera& cam, double diag, const char* label) {
    std::vector<std::string> report;
    EXPECT_TRUE(bakeModes(packPath, packPath, {RenderMode::kExact}, report).isOk());
    PackReader p;
    EXPECT_TRUE(p.open(packPath).isOk());
    Renderer r;
    EXPECT_TRUE(r.init(p).isOk());
    EXPECT_TRUE(r.modeReady(RenderMode::kExact));
    RenderSettings rs;
    rs.mode = RenderMode::kExact;
    rs.countWork = true;
    rs.cull.subpixelSplats = false;  // every box ray-cast: the mode itself is compared, not the splat LOD
    FrameResult fr;
    Status s = r.render(cam, rs, fr, true);
    EXPECT_TRUE(s.isOk()) << s.message();
    EXPECT_EQ(fr.stats.drawnMode, RenderMode::kExact);
    const auto ref = test::cpuDepth(p, cam);
    const test::Agreement a = test::agreement(fr.depth, ref, 1e-4 * diag);
    const test::Agreement a3 = test::agreement(fr.depth, ref, 1e-3 * diag);
    const WorkCounters& w = fr.stats.work;
    std::printf("[exact-gl] %-34s covered %6zu  within 1e-4 diag %7.3f%% (1e-3: %7.3f%%)  coverage differs %4zu  max %.3g  "
                "nodes/ray mean %.1f p99 %u max %u capped %llu\n",
                label, a.covered, a.covered ? 100.0 * double(a.agree) / double(a.covered) : 0.0,
                a.covered ? 100.0 * double(a3.agree) / double(a3.covered) : 0.0, a.coverageDiffers, a.maxErr,
                w.mean(), w.p99, w.max, (unsigned long long)w.capped);
    totals_.covered += a.covered;
    totals_.agree += a.agree;
    totals_.coverageDiffers += a.coverageDiffers;
    totals_.work.add(w);
    return a;
  }

  void bumpyPlane(std::vector<Eigen::Vector3d>& pts, std::vector<Eigen::Vector3d>& nrm, bool holes) {
    const int n = 240;
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double x = -1 + 2.0 * i / (n - 1), y = -1 + 2.0 * j / (n - 1);
        if (holes && (std::pow(x - 0.3, 2) + std::pow(y + 0.2, 2) < 0.04 || std::abs(x + 0.4) < 0.03)) continue;
        const double amp = 0.05, z = amp * std::sin(3 * x) * std::cos(2 * y);
        pts.emplace_back(x, y, z);
        nrm.push_back(Eigen::Vector3d(-amp * 3 * std::cos(3 * x) * std::cos(2 * y), amp * 2 * std::sin(3 * x) * std::sin(2 * y), 1)
                          .normalized());
      }
  }

  Totals totals_;
  test::TempDir dir_;
};

TEST_F(ExactGl, GrazingViewsOverAPlaneWithHoles) {
  std::vector<Eigen::Vector3d> pts, nrm;
  bumpyPlane(pts, nrm, true);
  const std::string pack = test::packPoints(dir_, pts, nrm, "plane");
  for (double deg : {60.0, 80.0, 85.0, 89.0, 89.9}) {
    const double a = deg * M_PI / 180;
    Camera cam;
    cam.target = Eigen::Vector3d(0, 0, 0);
    cam.eye = cam.target + 3.0 * Eigen::Vector3d(std::sin(a), 0.1 * std::sin(a), std::cos(a)).normalized();
    cam.up = Eigen::Vector3d::UnitZ();
    cam.width = cam.height = 96;
    cam.fovDeg = 30;
    char label[64];
    std::snprintf(label, sizeof(label), "grazing %.1f deg", deg);
    const test::Agreement g = run(pack, cam, 2.83, label);
    EXPECT_GE(double(g.agree), 0.999 * double(g.covered)) << label;
  }
}

TEST_F(ExactGl, RaysAlongFacesAndCamerasOnFacesAndInside) {
  std::vector<Eigen::Vector3d> pts, nrm;
  bumpyPlane(pts, nrm, false);
  const std::string pack = test::packPoints(dir_, pts, nrm, "plane2");
  PackReader p;
  ASSERT_TRUE(p.open(pack).isOk());
  ASSERT_EQ(p.cells().size(), 1u);
  const CellRecord c = p.cells()[0];
  const Eigen::Vector3d O = Eigen::Vector3d(p.meta().origin) + Eigen::Vector3d(c.origin), U(c.u), V(c.v), W(c.w);
  auto world = [&](double u, double v, double w) { return O + U * u + V * v + W * w; };
  const double wTop = c.box[5], uMax = c.box[1], vMax = c.box[3];
  struct Case {
    const char* name;
    Eigen::Vector3d eye, target;
  } cases[] = {
      {"ray along the top face", world(uMax + 1, 0, wTop), world(0, 0, wTop)},
      {"ray along a top edge", world(uMax + 1, vMax, wTop), world(0, vMax, wTop)},
      {"ray through a top corner", world(uMax + 1, vMax + 1, wTop + 0.05), world(uMax, vMax, wTop)},
      {"camera exactly on the top face", world(0.3, 0.2, wTop), world(0.5, 0.4, 0.0)},
      {"camera exactly on a side face", world(uMax, 0.1, 0.0), world(0.0, 0.0, -0.02)},
      {"camera inside the box", world(-0.2, 0.1, wTop * 0.9), world(0.4, 0.3, -0.05)},
  };
  for (const Case& k : cases) {
    Camera cam;
    cam.eye = k.eye;
    cam.target = k.target;
    cam.up = W;
    if (cam.forward().cross(cam.up).norm() < 1e-6) cam.up = U;
    cam.width = cam.height = 80;
    cam.fovDeg = 60;
    const test::Agreement a = run(pack, cam, 2.83, k.name);
    EXPECT_GE(double(a.agree), 0.999 * double(a.covered)) << k.name;
  }
}

TEST_F(ExactGl, TallSpikeAndDegenerateCells) {
  std::vector<Eigen::Vector3d> pts, nrm;
  for (int j = 0; j < 200; ++j)
    for (int i = 0; i < 200; ++i) {
      const double x = -1 + i / 100.0, y = -1 + j / 100.0;
      const double r2 = std::pow(x - 0.2, 2) + std::pow(y + 0.1, 2);
      const double z = 0.4 * std::exp(-r2 / 0.01);
      pts.emplace_back(x, y, z);
      const double dzdx = -z * 2 * (x - 0.2) / 0.01, dzdy = -z * 2 * (y + 0.1) / 0.01;
      nrm.push_back(Eigen::Vector3d(-dzdx, -dzdy, 1).normalized());
    }
  const std::string spike = test::packPoints(dir_, pts, nrm, "spike");
  Camera cam;
  cam.eye = Eigen::Vector3d(1.8, -1.5, 1.4);
  cam.target = Eigen::Vector3d(0.2, -0.1, 0.1);
  cam.up = Eigen::Vector3d::UnitZ();
  cam.width = cam.height = 96;
  const test::Agreement a = run(spike, cam, 2.9, "spike 0.4 tall on a 2x2 plane");
  EXPECT_LE(a.coverageDiffers, 2u);
  EXPECT_GE(double(a.agree), 0.999 * double(a.covered));
  // Degenerate cells: a few points, collinear points, an isotropic blob.
  std::vector<std::vector<Eigen::Vector3d>> cases = {{{1, 2, 3}, {1.001, 2, 3}, {1, 2.001, 3}}, {}, {}};
  std::mt19937 rng(3);
  std::normal_distribution<double> N(0, 1);
  for (int i = 0; i < 500; ++i) {
    cases[1].emplace_back(i * 0.001, i * 0.002, -i * 0.001);
    cases[2].push_back(Eigen::Vector3d(N(rng), N(rng), N(rng)).normalized() * 0.1);
  }
  for (size_t k = 0; k < cases.size(); ++k) {
    std::vector<Eigen::Vector3d> n(cases[k].size(), Eigen::Vector3d::UnitZ());
    const std::string pack = test::packPoints(dir_, cases[k], n, "deg" + std::to_string(k));
    PackReader p;
    ASSERT_TRUE(p.open(pack).isOk());
    Eigen::Vector3d lo = Eigen::Vector3d(p.meta().boundsMin) + Eigen::Vector3d(p.meta().origin);
    Eigen::Vector3d hi = Eigen::Vector3d(p.meta().boundsMax) + Eigen::Vector3d(p.meta().origin);
    const double diag = std::max((hi - lo).norm(), 1e-3);
    for (const Camera& c : orbitCameras(lo, hi, 2, Eigen::Vector3d::UnitY(), 40, 48, 48)) {
      const test::Agreement d = run(pack, c, diag, k == 0 ? "degenerate: 3 points" : k == 1 ? "degenerate: collinear" : "degenerate: isotropic");
      EXPECT_GE(double(d.agree), 0.999 * double(d.covered));
    }
  }
}

TEST_F(ExactGl, BunnyScansOrbit) {
  ASSERT_TRUE(test::haveSharedData()) << "../shared/data is missing";
  auto in = InputSet::open({test::sharedData("stanford_bunny/scans/bun.conf")});
  ASSERT_TRUE(in.isOk());
  PackSummary sum;
  ASSERT_TRUE(packInput(*in, dir_.file("bunny.hfa"), PackOptions{}, nullptr, sum).isOk());
  PackReader p;
  ASSERT_TRUE(p.open(dir_.file("bunny.hfa")).isOk());
  Eigen::Vector3d lo = Eigen::Vector3d(p.meta().boundsMin) + Eigen::Vector3d(p.meta().origin);
  Eigen::Vector3d hi = Eigen::Vector3d(p.meta().boundsMax) + Eigen::Vector3d(p.meta().origin);
  for (const Camera& c : orbitCameras(lo, hi, 3, p.viewUp(), 40, 160, 160)) {
    const test::Agreement a = run(dir_.file("bunny.hfa"), c, (hi - lo).norm(), "bunny scans orbit");
    EXPECT_GE(double(a.agree), 0.999 * double(a.covered));
  }
}

}  // namespace
}  // namespace sa
