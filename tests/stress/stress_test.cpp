// Numerical stress suite. Every case asserts on a measured error number and prints it:
// grazing rays, rays along box faces and through corners, cameras on a face and inside a
// box, degenerate cells, georeferenced offsets, tiny and huge objects, extreme height ranges,
// 1-texel and maximal tiles, non-finite input, and the GLSL ray transform against a
// double-precision CPU ray cast over thousands of random rays.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "../common/render_util.h"
#include "viewer/egl_context.h"
#include "viewer/renderer.h"

namespace sa {
namespace {

class Stress : public test::GlTest {
 protected:

  // Renders `cam` on the GPU and on the CPU; returns the agreement within tol.
  test::Agreement compare(const std::string& packPath, const Camera& cam, double tol, const char* label,
                          RenderSettings rs = {}) {
    PackReader p;
    EXPECT_TRUE(p.open(packPath).isOk());
    Renderer r;
    EXPECT_TRUE(r.init(p).isOk());
    FrameResult fr;
    Status s = r.render(cam, rs, fr, true);
    EXPECT_TRUE(s.isOk()) << s.message();
    const auto ref = test::cpuDepth(p, cam);
    const test::Agreement a = test::agreement(fr.depth, ref, tol);
    std::printf("[stress] %-44s covered %6zu  agree %6.2f%%  coverage differs %5zu  max %.3g  p99 %.3g\n", label,
                a.covered, a.covered ? 100.0 * a.agree / a.covered : 0.0, a.coverageDiffers, a.maxErr, a.p99Err);
    return a;
  }

  // A bumpy 2x2 plane (one height field) with exact normals, scaled by s and offset.
  void bumpyPlane(double s, const Eigen::Vector3d& off, double amp, std::vector<Eigen::Vector3d>& pts,
                  std::vector<Eigen::Vector3d>& nrm, int n = 240) {
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double x = -1 + 2.0 * i / (n - 1), y = -1 + 2.0 * j / (n - 1);
        const double z = amp * std::sin(3 * x) * std::cos(2 * y);
        pts.push_back(off + s * Eigen::Vector3d(x, y, z));
        nrm.push_back(Eigen::Vector3d(-amp * 3 * std::cos(3 * x) * std::cos(2 * y), amp * 2 * std::sin(3 * x) * std::sin(2 * y), 1).normalized());
      }
  }

  test::TempDir dir_;
};

double fraction(const test::Agreement& a) { return a.covered ? double(a.agree) / double(a.covered) : 0; }

TEST_F(Stress, GrazingRaysUpTo89point9Degrees) {
  std::vector<Eigen::Vector3d> pts, nrm;
  bumpyPlane(1, Eigen::Vector3d::Zero(), 0.05, pts, nrm);
  const std::string pack = test::packPoints(dir_, pts, nrm, "plane");
  for (double deg : {60.0, 80.0, 85.0, 89.0, 89.9}) {
    // deg = angle between the view ray and the plane normal.
    const double a = deg * M_PI / 180;
    Camera cam;
    cam.target = Eigen::Vector3d(0, 0, 0);
    cam.eye = cam.target + 3.0 * Eigen::Vector3d(std::sin(a), 0.1 * std::sin(a), std::cos(a)).normalized();
    cam.up = Eigen::Vector3d::UnitZ();
    cam.width = cam.height = 96;
    cam.fovDeg = 30;
    char label[64];
    std::snprintf(label, sizeof(label), "grazing %.1f deg, 12 steps", deg);
    const test::Agreement g = compare(pack, cam, 1e-3 * 2.83, label);
    if (deg < 89.5) {
      EXPECT_GT(g.covered, 50u);
    }
    // Long rays over a bumpy field: the linear search may step over a crest the exact cast
    // hits (then the GPU hits the surface farther on). Bounded fractions, measured.
    EXPECT_GE(fraction(g), deg <= 85 ? 0.97 : 0.80) << label;
    RenderSettings fine;
    fine.iterations = 64;
    fine.cull.adaptiveSteps = false;
    std::snprintf(label, sizeof(label), "grazing %.1f deg, 64 steps", deg);
    const test::Agreement f = compare(pack, cam, 1e-3 * 2.83, label, fine);
    EXPECT_GE(fraction(f), deg <= 85 ? 0.99 : 0.90) << label;
  }
}

TEST_F(Stress, RaysAlongFacesEdgesAndCornersAndCamerasOnFacesAndInside) {
  std::vector<Eigen::Vector3d> pts, nrm;
  bumpyPlane(1, Eigen::Vector3d::Zero(), 0.05, pts, nrm);
  const std::string pack = test::packPoints(dir_, pts, nrm, "plane2");
  PackReader p;
  ASSERT_TRUE(p.open(pack).isOk());
  ASSERT_EQ(p.cells().size(), 1u);
  const CellRecord& c = p.cells()[0];
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
    const test::Agreement a = compare(pack, cam, 1e-3 * 2.83, k.name);
    if (a.covered > 0) {
      EXPECT_GE(fraction(a), 0.90) << k.name;
      EXPECT_LE(a.coverageDiffers, a.covered / 10) << k.name;
    }
  }
}

TEST_F(Stress, DegenerateCellsPackAndRenderWithoutNaN) {
  struct Case {
    const char* name;
    std::vector<Eigen::Vector3d> pts;
  };
  std::vector<Case> cases;
  cases.push_back({"1 point", {{1, 2, 3}}});
  cases.push_back({"2 points", {{1, 2, 3}, {1.001, 2, 3}}});
  cases.push_back({"3 points", {{1, 2, 3}, {1.001, 2, 3}, {1, 2.001, 3}}});
  Case line{"collinear", {}}, dup{"all duplicates", {}}, iso{"near-equal eigenvalues", {}}, split{"points on split planes", {}};
  std::mt19937 rng(3);
  std::normal_distribution<double> N(0, 1);
  for (int i = 0; i < 500; ++i) {
    line.pts.emplace_back(i * 0.001, i * 0.002, -i * 0.001);
    dup.pts.emplace_back(5e5 + 0.125, 5e6 + 0.25, 100.5);
    iso.pts.push_back(Eigen::Vector3d(N(rng), N(rng), N(rng)).normalized() * 0.1);  // isotropic: λ0 ≈ λ1 ≈ λ2
    split.pts.emplace_back((i % 3) * 0.5 - 0.5, ((i / 3) % 3) * 0.5 - 0.5, 0.0);  // on the cube's mid planes
  }
  cases.push_back(line);
  cases.push_back(dup);
  cases.push_back(iso);
  cases.push_back(split);
  for (const Case& k : cases) {
    std::vector<Eigen::Vector3d> nrm(k.pts.size(), Eigen::Vector3d::UnitZ());
    PackSummary sum;
    const std::string name = std::string("deg") + std::to_string(&k - cases.data());
    const std::string pack = test::packPoints(dir_, k.pts, nrm, name, {}, &sum);
    PackReader p;
    ASSERT_TRUE(p.open(pack).isOk()) << k.name;
    double orthoErr = 0;
    for (const CellRecord& c : p.cells()) {
      const Eigen::Vector3d U(c.u), V(c.v), W(c.w);
      for (double v : c.box) ASSERT_TRUE(std::isfinite(v)) << k.name;
      for (double v : c.origin) ASSERT_TRUE(std::isfinite(v)) << k.name;
      orthoErr = std::max({orthoErr, std::abs(U.norm() - 1), std::abs(V.norm() - 1), std::abs(W.norm() - 1),
                           std::abs(U.dot(V)), std::abs(U.dot(W)), std::abs(V.dot(W))});
    }
    std::printf("[stress] degenerate %-22s %4u points -> %3u cells (%u degenerate), frame orthonormality error %.2g\n",
                k.name, unsigned(sum.pointsRead), sum.cells, sum.degenerateCells, orthoErr);
    EXPECT_LT(orthoErr, 1e-12) << k.name;
    Renderer r;
    ASSERT_TRUE(r.init(p).isOk());
    Eigen::Vector3d lo(p.meta().boundsMin), hi(p.meta().boundsMax);
    lo += Eigen::Vector3d(p.meta().origin);
    hi += Eigen::Vector3d(p.meta().origin);
    auto cams = orbitCameras(lo, hi, 2, Eigen::Vector3d::UnitY(), 40, 48, 48);
    for (const Camera& cam : cams) {
      FrameResult fr;
      ASSERT_TRUE(r.render(cam, RenderSettings{}, fr, true).isOk()) << k.name;
      for (float d : fr.depth) ASSERT_FALSE(std::isnan(d)) << k.name;
    }
  }
}

TEST_F(Stress, GeoreferencedOffsetsRenderTheSameImage) {
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(20000, 1.0, Eigen::Vector3d::Zero(), pts, nrm);
  PackOptions opt;
  opt.texelSize = 0.01;
  Camera cam;
  cam.eye = Eigen::Vector3d(0.5, 1.0, 3.0);
  cam.target = Eigen::Vector3d::Zero();
  cam.width = cam.height = 96;
  auto renderAt = [&](const Eigen::Vector3d& off, const std::string& name) {
    std::vector<Eigen::Vector3d> moved = pts;
    for (auto& q : moved) q += off;
    PackReader p;
    EXPECT_TRUE(p.open(test::packPoints(dir_, moved, nrm, name, opt)).isOk());
    Renderer r;
    EXPECT_TRUE(r.init(p).isOk());
    Camera c = cam;
    c.eye += off;
    c.target += off;
    FrameResult fr;
    EXPECT_TRUE(r.render(c, RenderSettings{}, fr, true).isOk());
    return fr.depth;
  };
  const auto base = renderAt(Eigen::Vector3d::Zero(), "geo0");
  const double diag = Eigen::Vector3d(2, 2, 2).norm();
  for (const Eigen::Vector3d& off : {Eigen::Vector3d(5e5, 5e6, 1e2), Eigen::Vector3d(1e7, 1e7, 1e7)}) {
    const auto d = renderAt(off, "geo" + std::to_string(off.x()));
    size_t differ = 0, both = 0;
    double maxDiff = 0;
    for (size_t i = 0; i < d.size(); ++i) {
      const bool a = std::isfinite(base[i]), b = std::isfinite(d[i]);
      differ += a != b;
      if (a && b) {
        ++both;
        maxDiff = std::max(maxDiff, std::abs(double(base[i]) - d[i]));
      }
    }
    std::printf("[stress] offset (%.0e, %.0e, %.0e): coverage differs on %zu of %zu px, max depth diff %.2g of the diagonal\n",
                off.x(), off.y(), off.z(), differ, both, maxDiff / diag);
    EXPECT_GT(both, 1000u);
    EXPECT_LE(differ, both / 500);
    EXPECT_LE(maxDiff, 1e-4 * diag);
  }
}

TEST_F(Stress, TinyAndHugeObjects) {
  for (double scale : {1e-6, 1e4}) {
    std::vector<Eigen::Vector3d> pts, nrm;
    test::spherePoints(20000, scale, Eigen::Vector3d(scale * 3, -scale, scale * 2), pts, nrm);
    const std::string pack = test::packPoints(dir_, pts, nrm, scale < 1 ? "tiny" : "huge");
    Camera cam;
    cam.target = Eigen::Vector3d(scale * 3, -scale, scale * 2);
    cam.eye = cam.target + scale * Eigen::Vector3d(0.4, 1.0, 3.2);
    cam.width = cam.height = 80;
    char label[64];
    std::snprintf(label, sizeof(label), "sphere of radius %.0e m", scale);
    const test::Agreement a = compare(pack, cam, 1e-3 * 3.46 * scale, label);
    EXPECT_GT(a.covered, 1000u);
    EXPECT_GE(fraction(a), 0.98) << label;
  }
}

TEST_F(Stress, ExtremeHeightRangesAndTileSizes) {
  // Tall spikes (the paper's "tall mountains"): a plane with narrow peaks 40x its bumps.
  {
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
    PackSummary sum;
    const std::string pack = test::packPoints(dir_, pts, nrm, "spike", {}, &sum);
    Camera cam;
    cam.eye = Eigen::Vector3d(1.8, -1.5, 1.4);
    cam.target = Eigen::Vector3d(0.2, -0.1, 0.1);
    cam.up = Eigen::Vector3d::UnitZ();
    cam.width = cam.height = 96;
    const test::Agreement a = compare(pack, cam, 1e-3 * 2.9, "spike 0.4 tall on a 2x2 plane");
    std::printf("[stress] spike: %u cells\n", sum.cells);
    EXPECT_GE(fraction(a), 0.97);
  }
  // One-texel tiles and a maximal (4094-texel) tile.
  for (double texel : {50.0, 2.0 / 4000}) {
    std::vector<Eigen::Vector3d> pts, nrm;
    bumpyPlane(1, Eigen::Vector3d::Zero(), 0.0, pts, nrm, 200);
    PackOptions opt;
    opt.texelSize = texel;
    opt.coverageRadius = 3;
    const std::string pack = test::packPoints(dir_, pts, nrm, texel > 1 ? "onetexel" : "maxtile", opt);
    PackReader p;
    ASSERT_TRUE(p.open(pack).isOk());
    uint32_t maxSide = 0;
    for (const CellRecord& c : p.cells()) maxSide = std::max<uint32_t>({maxSide, c.tileW, c.tileH});
    Camera cam;
    cam.eye = Eigen::Vector3d(0.3, -0.8, 2.5);
    cam.target = Eigen::Vector3d::Zero();
    cam.up = Eigen::Vector3d::UnitZ();
    cam.width = cam.height = 64;
    char label[64];
    std::snprintf(label, sizeof(label), "flat plane, largest tile %u texels", maxSide);
    const test::Agreement a = compare(pack, cam, 1e-3 * 2.83, label);
    if (texel > 1) EXPECT_EQ(maxSide, 1u);
    else EXPECT_GE(maxSide, 4000u);
    EXPECT_GT(a.covered, 500u);
    EXPECT_GE(fraction(a), 0.99);
  }
}

TEST_F(Stress, NonFiniteInputSkippedCountedOrRejectedWhenStrict) {
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(2000, 1.0, Eigen::Vector3d::Zero(), pts, nrm);
  for (int i = 0; i < 2000; i += 100) pts[size_t(i)] = Eigen::Vector3d(i % 200 ? NAN : INFINITY, 0, -INFINITY);
  test::writePointsPly(dir_.file("nan.ply"), pts, &nrm);
  auto in = InputSet::open({dir_.file("nan.ply")});
  ASSERT_TRUE(in.isOk());
  PackSummary sum;
  ASSERT_TRUE(packInput(*in, dir_.file("nan.hfa"), PackOptions{}, nullptr, sum).isOk());
  std::printf("[stress] non-finite: %llu of %d points skipped and counted\n", (unsigned long long)sum.pointsSkipped, 2000);
  EXPECT_EQ(sum.pointsSkipped, 20u);
  EXPECT_EQ(sum.pointsRead, 1980u);
  PackReader p;
  ASSERT_TRUE(p.open(dir_.file("nan.hfa")).isOk());
  for (int a = 0; a < 3; ++a) EXPECT_LT(std::abs(p.meta().boundsMax[a]), 1.01);
  PackOptions strict;
  strict.strict = true;
  Status s = packInput(*in, dir_.file("strict.hfa"), strict, nullptr, sum);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("nan.ply: vertex 0"), std::string::npos) << s.message();
}

// Thousands of random rays: every pixel of random views is one ray, cast by the GLSL shader
// (float, camera-relative) and by the CPU in double.
TEST_F(Stress, GlslRayTransformAgainstDoubleCpuCast) {
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(30000, 1.0, Eigen::Vector3d(512345.0, 5012345.0, 250.0), pts, nrm);
  const std::string pack = test::packPoints(dir_, pts, nrm, "rays");
  PackReader p;
  ASSERT_TRUE(p.open(pack).isOk());
  Renderer r;
  ASSERT_TRUE(r.init(p).isOk());
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> U(-1, 1);
  std::vector<double> errs;
  size_t rays = 0, coverage = 0;
  const Eigen::Vector3d c(512345.0, 5012345.0, 250.0);
  RenderSettings fine;  // enough steps that the linear search is not what is measured
  fine.iterations = 48;
  fine.cull.adaptiveSteps = false;
  for (int v = 0; v < 6; ++v) {
    Camera cam;
    Eigen::Vector3d dir(U(rng), U(rng), U(rng));
    cam.eye = c + dir.normalized() * (2.0 + 2 * std::abs(U(rng)));
    cam.target = c + 0.3 * Eigen::Vector3d(U(rng), U(rng), U(rng));
    cam.width = cam.height = 48;
    FrameResult fr;
    ASSERT_TRUE(r.render(cam, fine, fr, true).isOk());
    const auto ref = test::cpuDepth(p, cam);
    for (size_t i = 0; i < ref.size(); ++i) {
      ++rays;
      const bool a = std::isfinite(fr.depth[i]), b = std::isfinite(ref[i]);
      coverage += a != b;
      if (a && b) errs.push_back(std::abs(double(fr.depth[i]) - ref[i]) / 3.46);
    }
  }
  std::sort(errs.begin(), errs.end());
  const double p99 = errs[size_t(0.99 * double(errs.size() - 1))], maxE = errs.back();
  std::printf("[stress] GLSL vs CPU: %zu rays, %zu hits, hit/miss disagree on %zu; depth diff p99 %.2g, max %.2g of the diagonal\n",
              rays, errs.size(), coverage, p99, maxE);
  EXPECT_GT(errs.size(), 3000u);
  EXPECT_LE(p99, 1e-3);
  EXPECT_LE(coverage, rays / 100);
}

}  // namespace
}  // namespace sa
