// Accuracy on real data: the bunny packed from its 10 raw range scans (aligned by bun.conf),
// rendered on the GPU path from 4 orbit views at 512x512, against a depth render of Stanford's
// zippered reconstruction bun_zipper.ply (its triangles rasterized with the same cameras).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <utility>

#include "../common/test_util.h"
#include "preprocess/pipeline.h"
#include "preprocess/nearest.h"
#include "viewer/egl_context.h"
#include "viewer/eval.h"
#include "viewer/reference.h"
#include "viewer/renderer.h"
#include "viewer/source_points.h"

namespace sa {
namespace {

// Writes a triangle mesh as an ASCII PLY.
void writeMeshPly(const std::string& path, const std::vector<Eigen::Vector3d>& v, const std::vector<Eigen::Vector3i>& f) {
  std::string t = "ply\nformat ascii 1.0\nelement vertex " + std::to_string(v.size()) +
                  "\nproperty double x\nproperty double y\nproperty double z\nelement face " + std::to_string(f.size()) +
                  "\nproperty list uchar int vertex_indices\nend_header\n";
  char buf[128];
  for (const auto& p : v) {
    std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g\n", p.x(), p.y(), p.z());
    t += buf;
  }
  for (const auto& q : f) t += "3 " + std::to_string(q[0]) + " " + std::to_string(q[1]) + " " + std::to_string(q[2]) + "\n";
  test::writeText(path, t);
}

struct MeshViews {
  double iouMin = 1, depthMedMax = 0, depthP95Max = 0, seamOrbit = 0;
  size_t holes = 0, onlyRender = 0, surface = 0;
};

// Renders `cams` (colour, depth, normals and cell ids) and compares each with the mesh's own
// rasterized depth: interior holes, coverage, depth error; the seam ratio pooled over the views.
MeshViews compareWithMesh(Renderer& r, const TriangleMesh& mesh, const std::vector<Camera>& cams, double diag,
                          const char* name) {
  MeshViews out;
  SeamStats pooled;
  RenderSettings rs;
  for (size_t v = 0; v < cams.size(); ++v) {
    FrameResult fr;
    EXPECT_TRUE(r.render(cams[v], rs, fr, kReadColor | kReadDepth | kReadNormals | kReadCells).isOk());
    const ReferenceView ref = referenceView(mesh, cams[v]);
    const ViewMetrics m =
        evaluateView(fr.color, fr.depth, fr.normals, ref, shadeReference(ref, cams[v], rs.baseColor, rs.background), diag);
    const SeamStats s = seamStats(cams[v], fr.depth, fr.normals, fr.cells);
    pooled.borderMeanDeg += s.borderMeanDeg * double(s.borderPairs);
    pooled.insideMeanDeg += s.insideMeanDeg * double(s.insidePairs);
    pooled.borderPairs += s.borderPairs;
    pooled.insidePairs += s.insidePairs;
    if (m.interiorHoles || m.iou < 0.99 || m.depthMedian > 1e-5 || std::getenv("SA_TEST_VERBOSE"))
      std::printf("%s view %zu: %zu interior holes, IoU %.4f, median depth error %.2e\n", name, v, m.interiorHoles,
                  m.iou, m.depthMedian);
    out.iouMin = std::min(out.iouMin, m.iou);
    out.depthMedMax = std::max(out.depthMedMax, m.depthMedian);
    out.depthP95Max = std::max(out.depthP95Max, m.depthP95);
    out.holes += m.interiorHoles;
    out.onlyRender += m.onlyTest;
    out.surface += m.both + m.onlyRef;
  }
  if (pooled.borderPairs && pooled.insidePairs)
    out.seamOrbit = (pooled.borderMeanDeg / double(pooled.borderPairs)) / (pooled.insideMeanDeg / double(pooled.insidePairs));
  std::printf("%s: %zu views, worst IoU %.5f, worst median depth error %.2e, worst p95 %.2e of the diagonal, "
              "%zu interior holes, %zu pixels only in the render, seam ratio %.3f\n",
              name, cams.size(), out.iouMin, out.depthMedMax, out.depthP95Max, out.holes, out.onlyRender, out.seamOrbit);
  return out;
}

std::vector<Camera> closeUps(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, int count, double zoom, int size) {
  auto cams = orbitCameras(lo, hi, count, Eigen::Vector3d::UnitY(), 30, size, size);
  for (Camera& c : cams) c.eye = c.target + (c.eye - c.target) / zoom;
  return cams;
}

// A mesh file packed with the default options and ready to render and compare: the pack, the
// mesh itself as the reference, a GL context and a renderer.
struct MeshScene {
  PackSummary sum;
  PackReader pack;
  TriangleMesh mesh;
  EglContext ctx;
  Renderer r;
};

void openMeshScene(const std::string& src, const std::string& packPath, MeshScene& s) {
  auto input = InputSet::open({src});
  ASSERT_TRUE(input.isOk()) << input.status().message();
  ASSERT_TRUE(packInput(*input, packPath, PackOptions{}, nullptr, s.sum).isOk());
  ASSERT_TRUE(s.pack.open(packPath).isOk());
  auto mesh = loadMesh(src);
  ASSERT_TRUE(mesh.isOk()) << mesh.status().message();
  s.mesh = std::move(*mesh);
  ASSERT_TRUE(s.ctx.init().isOk());
  ASSERT_TRUE(s.r.init(s.pack).isOk());
}

// The triangle path: the dragon mesh rasterized into height maps, against the same mesh. A
// watertight mesh must render with no interior hole from any view: 24 orbit views and 8
// close-ups at 1024x1024, and the issue's close-up (517 pinholes before the per-vertex cone
// test, the 64-step march and stored normals; 88 over these 32 views before the cone test).
TEST(Accuracy, DragonMeshTrianglePathAgainstItself) {
  ASSERT_TRUE(test::haveSharedData()) << "../shared/data is missing";
  test::TempDir dir;
  MeshScene sc;
  openMeshScene(test::sharedData("stanford_dragon/reconstruction/dragon_vrip.ply"), dir.file("d.hfa"), sc);
  if (HasFatalFailure()) return;
  EXPECT_TRUE(sc.sum.fromTriangles);
  const PackSummary& sum = sc.sum;
  const TriangleMesh* mesh = &sc.mesh;
  Renderer& r = sc.r;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (size_t i = 0; i < mesh->positions.size(); i += 3) {
    lo = lo.cwiseMin(Eigen::Vector3d(&mesh->positions[i]));
    hi = hi.cwiseMax(Eigen::Vector3d(&mesh->positions[i]));
  }
  const double diag = (hi - lo).norm();
  std::printf("dragon: %u cells (%u forced)\n", sum.cells, sum.forcedCells);
  const MeshViews orbit =
      compareWithMesh(r, *mesh, orbitCameras(lo, hi, 24, Eigen::Vector3d::UnitY(), 40, 1024, 1024), diag, "dragon orbit");
  auto near = closeUps(lo, hi, 8, 4, 1024);
  Camera issue = near[0];
  issue.eye = Eigen::Vector3d(-0.02, 0.16, 0.16);
  issue.target = Eigen::Vector3d(-0.02, 0.13, 0);
  near.push_back(issue);
  const MeshViews close = compareWithMesh(r, *mesh, near, diag, "dragon close-ups");
  EXPECT_EQ(orbit.holes, 0u);
  EXPECT_EQ(close.holes, 0u);
  EXPECT_GE(orbit.iouMin, 0.998);
  EXPECT_GE(close.iouMin, 0.998);
  EXPECT_LE(orbit.depthMedMax, 1e-5);
  EXPECT_LE(close.depthMedMax, 1e-5);
  // Mean shading-normal angle across cell borders over that within cells (1 = no seam): 1.5
  // over the orbit, 2.3 close up, where the within-cell angle between pixels is tiny. The
  // neighbouring cells' normal fields still differ by about 1 degree at the same point.
  EXPECT_LE(orbit.seamOrbit, 1.8);
  EXPECT_LE(close.seamOrbit, 2.8);
}

// A real scanned bust (Cyberware's Igea, 268686 triangles as one triangle strip), not tuned on:
// 16 orbit views and 4 close-ups from 20 degrees above (it is open at the neck, and height
// fields are one-sided, so not from below), 768x768.
TEST(Accuracy, IgeaBustHasNoInteriorHoles) {
  ASSERT_TRUE(test::haveSharedData()) << "../shared/data is missing";
  test::TempDir dir;
  MeshScene sc;
  openMeshScene(test::sharedData("igea/igea.ply"), dir.file("igea.hfa"), sc);
  if (HasFatalFailure()) return;
  const PackSummary& sum = sc.sum;
  const PackReader& pack = sc.pack;
  const TriangleMesh* mesh = &sc.mesh;
  Renderer& r = sc.r;
  const Eigen::Vector3d o(pack.meta().origin);
  const Eigen::Vector3d lo = o + Eigen::Vector3d(pack.meta().boundsMin), hi = o + Eigen::Vector3d(pack.meta().boundsMax);
  auto cams = orbitCameras(lo, hi, 16, pack.viewUp(), 40, 768, 768);
  for (const Camera& c : closeUps(lo, hi, 4, 4, 768)) cams.push_back(c);
  const MeshViews m = compareWithMesh(r, *mesh, cams, (hi - lo).norm(), "igea");
  EXPECT_NEAR(sum.up.y(), 1.0, 1e-12);
  EXPECT_EQ(m.holes, 0u);
  EXPECT_GE(m.iouMin, 0.995);
  EXPECT_LE(m.depthMedMax, 1e-5);
}

// A scanned bust's coarse base: fine detail (a bumpy sphere, edges ~0.013) on a box of 12
// triangles (edges 2, 150 times longer). Large triangles used to leave black holes and flat
// patches at the wrong depth on the base; the mesh is watertight, so: no interior holes, and the
// depth of every pixel matches the mesh's own rasterization.
TEST(Accuracy, CoarseBaseUnderFineDetailIsExact) {
  test::TempDir dir;
  std::vector<Eigen::Vector3d> v;
  std::vector<Eigen::Vector3i> f;
  // The base: the box [-1,1] x [0,0.6] x [-1,1], two triangles a face, outward winding.
  for (int i = 0; i < 8; ++i) v.emplace_back(i & 1 ? 1 : -1, i & 2 ? 0.6 : 0, i & 4 ? 1 : -1);
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    f.emplace_back(q[0], q[1], q[2]);
    f.emplace_back(q[0], q[2], q[3]);
  }
  // The head: a bumpy sphere of radius 0.6 about (0, 1.1, 0), 240 x 120 segments.
  const int nu = 240, nv = 120, first = int(v.size());
  const Eigen::Vector3d c(0, 1.1, 0);
  for (int j = 0; j <= nv; ++j)
    for (int i = 0; i < nu; ++i) {
      const double th = M_PI * j / nv, ph = 2 * M_PI * i / nu;
      const double rad = 0.6 * (1 + 0.03 * std::sin(9 * ph) * std::sin(7 * th));
      v.push_back(c + rad * Eigen::Vector3d(std::sin(th) * std::cos(ph), std::cos(th), std::sin(th) * std::sin(ph)));
    }
  auto at = [&](int i, int j) { return first + j * nu + (i % nu); };
  for (int j = 0; j < nv; ++j)
    for (int i = 0; i < nu; ++i) {
      if (j > 0) f.emplace_back(at(i, j), at(i + 1, j), at(i, j + 1));
      if (j < nv - 1) f.emplace_back(at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
    }
  writeMeshPly(dir.file("bust.ply"), v, f);
  MeshScene sc;
  openMeshScene(dir.file("bust.ply"), dir.file("bust.hfa"), sc);
  if (HasFatalFailure()) return;
  EXPECT_TRUE(sc.sum.fromTriangles);
  const PackSummary& sum = sc.sum;
  const TriangleMesh* mesh = &sc.mesh;
  Renderer& r = sc.r;
  const Eigen::Vector3d lo(-1, 0, -1), hi(1, 1.75, 1);
  const double diag = (hi - lo).norm();
  auto cams = orbitCameras(lo, hi, 8, Eigen::Vector3d::UnitY(), 40, 512, 512);
  for (Camera c : orbitCameras(lo, hi, 4, Eigen::Vector3d::UnitY(), 40, 512, 512)) {
    c.eye.y() = -0.8;  // from below the base's plane: its underside
    cams.push_back(c);
  }
  const MeshViews m = compareWithMesh(r, *mesh, cams, diag, "bust");
  std::vector<Camera> corners;
  for (const Camera& c : closeUps(lo, hi, 4, 3, 512)) {
    Camera base = c;  // close to the base's top face, edges and corners
    base.target = Eigen::Vector3d(0.7, 0.6, 0.7);
    corners.push_back(base);
  }
  const MeshViews near = compareWithMesh(r, *mesh, corners, diag, "bust base close-ups");
  std::printf("bust: %u cells, up %.2f %.2f %.2f\n", sum.cells, sum.up.x(), sum.up.y(), sum.up.z());
  // A closed object: its normals sum to zero, so up is the format's +y, not a sign from noise
  // (it came out -y, the bust on its head).
  EXPECT_NEAR(sum.up.y(), 1.0, 1e-12);
  EXPECT_EQ(m.holes, 0u);
  EXPECT_GE(m.iouMin, 0.99);
  EXPECT_LE(m.depthMedMax, 1e-5);
  EXPECT_LE(m.depthP95Max, 1e-4);
  EXPECT_LE(near.depthMedMax, 1e-5);
  EXPECT_LE(near.depthP95Max, 1e-4);
  // Known limit: a cell may hold both faces of a 90-degree edge (its axis at 45 degrees), and
  // bilinear heights cut the ridge by up to half a texel, so the box's silhouette edges recede
  // by up to a texel (2.6 pixels in these close-ups) - counted as "interior" where the reference
  // is surface 3x3 around. Bound it: at most 0.1 % of the surface pixels.
  EXPECT_LE(double(near.holes), 0.001 * double(near.surface));
}

// An open bumpy sheet seen 80 degrees off its normal: the side of a height sheet is not a
// surface. The march once drew a wall from every coverage edge down to the bottom of the box.
TEST(Accuracy, OpenSheetSeenFromTheSideHasNoSkirt) {
  test::TempDir dir;
  std::vector<Eigen::Vector3d> v;
  std::vector<Eigen::Vector3i> f;
  const int n = 120;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = double(i) / n, z = double(j) / n;
      v.emplace_back(x, 0.03 * std::sin(11 * x) * std::cos(9 * z), z);
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i;
      f.emplace_back(a, a + n + 1, a + 1);
      f.emplace_back(a + 1, a + n + 1, a + n + 2);
    }
  writeMeshPly(dir.file("sheet.ply"), v, f);
  MeshScene sc;
  openMeshScene(dir.file("sheet.ply"), dir.file("sheet.hfa"), sc);
  if (HasFatalFailure()) return;
  const TriangleMesh* mesh = &sc.mesh;
  Renderer& r = sc.r;
  const Eigen::Vector3d lo(0, -0.03, 0), hi(1, 0.03, 1);
  std::vector<Camera> cams;
  for (int k = 0; k < 4; ++k) {
    // 80 degrees off the sheet's normal (+y), from each side. (Its underside is not drawn:
    // height fields are one-sided, like a closed mesh's back faces.)
    Camera c = orbitCameras(lo, hi, 1, Eigen::Vector3d::UnitY(), 40, 512, 512)[0];
    const double az = M_PI / 2 * k + 0.3, el = 10 * M_PI / 180;
    const double dist = 2.5;
    c.target = Eigen::Vector3d(0.5, 0, 0.5);
    c.eye = c.target + dist * Eigen::Vector3d(std::cos(el) * std::cos(az), std::sin(el), std::cos(el) * std::sin(az));
    cams.push_back(c);
  }
  const MeshViews m = compareWithMesh(r, *mesh, cams, (hi - lo).norm(), "sheet");
  EXPECT_GE(m.iouMin, 0.97);
  // The reference rasterizes both sides; a height field is one-sided, so where a grazing ray
  // passes under a bump at the border and sees the sheet's underside there is no surface (6
  // pixels in view 2). An open sheet is not watertight: bound these, do not demand zero.
  EXPECT_LE(double(m.holes), 0.0005 * double(m.surface));
  // Every drawn pixel lies on the sheet: a skirt would put pixels far below it (the render's
  // edge may reach half a texel past the mesh's border: a pixel-wide fringe, on the sheet).
  size_t drawn = 0, off = 0;
  for (const Camera& c : cams) {
    FrameResult fr;
    ASSERT_TRUE(r.render(c, RenderSettings{}, fr, kReadDepth).isOk());
    const std::vector<double> p = surfacePoints(c, fr.depth, Eigen::Vector3d::Zero());
    for (size_t i = 0; i < p.size(); i += 3) {
      const double x = std::clamp(p[i], 0.0, 1.0), z = std::clamp(p[i + 2], 0.0, 1.0);
      const double dy = p[i + 1] - 0.03 * std::sin(11 * x) * std::cos(9 * z);
      off += std::abs(dy) > 0.01 || std::abs(p[i] - x) > 0.01 || std::abs(p[i + 2] - z) > 0.01;
      ++drawn;
    }
  }
  std::printf("sheet: %zu of %zu drawn pixels off the sheet by more than 0.01\n", off, drawn);
  EXPECT_GT(drawn, 20000u);
  EXPECT_LE(double(off), 0.002 * double(drawn));
}

FarStats farOverOrbit(const PackReader& pack, int views, int size);

// The sparse sheet's pack against its mesh (compareWithMesh), and every drawn pixel on the
// sheet, within a fringe of 1.5 local spacings past its border (the coverage radius: 0.01 on
// the dense half, 0.04 on the sparse one): wider radii grow no blobs off it. Its own GL context.
template <class Height>
MeshViews sheetViews(const PackReader& pack, const TriangleMesh& mesh, const std::vector<Camera>& cams, double diag,
                     Height height, const char* name) {
  EglContext ctx;
  EXPECT_TRUE(ctx.init().isOk());
  Renderer r;
  EXPECT_TRUE(r.init(pack).isOk());
  const MeshViews m = compareWithMesh(r, mesh, cams, diag, name);
  size_t drawn = 0, off = 0, past = 0;
  for (const Camera& c : cams) {
    FrameResult fr;
    EXPECT_TRUE(r.render(c, RenderSettings{}, fr, kReadDepth).isOk());
    const std::vector<double> p = surfacePoints(c, fr.depth, Eigen::Vector3d::Zero());
    for (size_t i = 0; i < p.size(); i += 3, ++drawn) {
      const double x = std::clamp(p[i], -1.0, 1.0), y = std::clamp(p[i + 1], -1.0, 1.0);
      off += std::abs(p[i + 2] - height(x, y)) > 0.005;
      past += std::max(std::abs(p[i] - x), std::abs(p[i + 1] - y)) > (p[i] < 0 ? 0.01 : 0.04);
    }
  }
  std::printf("%s: of %zu drawn pixels %zu off the sheet, %zu past its fringe\n", name, drawn, off, past);
  EXPECT_LE(double(off), 0.002 * double(drawn));
  EXPECT_LE(double(past), 0.002 * double(drawn));
  return m;
}

// A sheet whose right half is sampled 16x more sparsely than its left (a terrestrial scan's far
// field, a second strip flown higher): by default the sparse half's samples keep radii near
// the pack's spacing and it renders as specks, and the pack says so; with --sparse-reach auto its
// surface-like samples' radii follow their spacing up to the reach it chose from them, and it
// renders as surface, on the sheet.
TEST(Accuracy, SparseHalfOfASheetIsSurfaceWithSparseReach) {
  test::TempDir dir;
  auto height = [](double x, double y) { return 0.05 * std::sin(3 * x) * std::cos(2 * y); };
  std::mt19937_64 rng(7);
  auto uniform = [&] { return double(rng() >> 11) * 0x1.0p-53; };
  std::string cloud;
  const int dense = 80000, sparse = 5000;
  cloud = "ply\nformat ascii 1.0\nelement vertex " + std::to_string(dense + sparse) +
          "\nproperty double x\nproperty double y\nproperty double z\nend_header\n";
  char buf[96];
  for (int i = 0; i < dense + sparse; ++i) {
    const double x = i < dense ? -uniform() : uniform(), y = 2 * uniform() - 1;
    std::snprintf(buf, sizeof buf, "%.9g %.9g %.9g\n", x, y, height(x, y) + 0.0005 * (uniform() - 0.5));
    cloud += buf;
  }
  test::writeText(dir.file("sheet.ply"), cloud);
  std::vector<Eigen::Vector3d> v;
  std::vector<Eigen::Vector3i> f;
  const int n = 100;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = -1 + 2.0 * i / n, y = -1 + 2.0 * j / n;
      v.emplace_back(x, y, height(x, y));
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i;
      f.emplace_back(a, a + 1, a + n + 2);
      f.emplace_back(a, a + n + 2, a + n + 1);
    }
  writeMeshPly(dir.file("ref.ply"), v, f);
  auto mesh = loadMesh(dir.file("ref.ply"));
  ASSERT_TRUE(mesh.isOk()) << mesh.status().message();
  auto input = InputSet::open({dir.file("sheet.ply")});
  ASSERT_TRUE(input.isOk()) << input.status().message();
  const Eigen::Vector3d lo(-1, -1, -0.05), hi(1, 1, 0.05);
  const std::vector<Camera> cams = orbitCameras(lo, hi, 4, Eigen::Vector3d::UnitZ(), 40, 512, 512);
  MeshViews views[2];
  double suggested = 0;
  for (int k = 0; k < 2; ++k) {
    PackOptions opt;
    opt.up = Eigen::Vector3d::UnitZ();
    opt.sparseReachAuto = k == 1;
    PackSummary sum;
    const std::string path = dir.file(k ? "reach.hfa" : "default.hfa");
    ASSERT_TRUE(packInput(*input, path, opt, nullptr, sum).isOk());
    // Both count the sparse half (5000 of 85000 points, 5.9 %, less its edge) as surfaces sampled
    // over 3 spacings apart. The default names the option that covers it and the reach auto
    // chooses; auto chooses the sparse half's median spacing in the pack's: its points are 4x as
    // far apart, and an area spacing is wider than the nearest neighbour's.
    EXPECT_GT(sum.sparseSurfaceShare, 0.04);
    EXPECT_LT(sum.sparseSurfaceShare, 0.062);
    const auto warning = std::find_if(sum.warnings.begin(), sum.warnings.end(), [](const std::string& w) {
      return w.find("--sparse-reach auto (here ") != std::string::npos;
    });
    EXPECT_EQ(warning != sum.warnings.end(), k == 0);
    if (k == 0 && warning != sum.warnings.end())
      suggested = std::atof(warning->c_str() + warning->find("(here ") + 6);
    if (k == 1) {
      std::printf("sparse sheet: --sparse-reach auto chose %.3f (suggested %.1f)\n", sum.sparseReach, suggested);
      EXPECT_GE(sum.sparseReach, 5.0);
      EXPECT_LE(sum.sparseReach, 9.0);
      EXPECT_NEAR(sum.sparseReach, suggested, 0.051);
    }
    PackReader pack;
    ASSERT_TRUE(pack.open(path).isOk());
    views[k] = sheetViews(pack, *mesh, cams, (hi - lo).norm(), height, k ? "sparse sheet, --sparse-reach auto" : "sparse sheet");
    if (HasFatalFailure()) return;
    // Nor surface far from every point in its own spacing (eval's '>3 loc').
    const FarStats far = farOverOrbit(pack, 4, 512);
    std::printf("sparse sheet (reach %.2f): beyond 3 spacings %.4f %%, beyond 3 local spacings %.4f %%\n",
                sum.sparseReach, 100 * far.beyond3, 100 * far.beyond3Local);
    EXPECT_LE(far.beyond3Local, 0.001);
  }
  EXPECT_LT(views[0].iouMin, 0.85);   // specks
  EXPECT_GE(views[1].iouMin, 0.97);   // surface
  EXPECT_LE(double(views[1].holes), 0.02 * double(views[0].holes));
}

TEST(Accuracy, BunnyRawScansAgainstZipperedMesh) {
  ASSERT_TRUE(test::haveSharedData()) << "../shared/data is missing";
  test::TempDir dir;
  auto input = InputSet::open({test::sharedData("stanford_bunny/scans/bun.conf")});
  ASSERT_TRUE(input.isOk()) << input.status().message();
  PackOptions opt;
  PackSummary sum;
  const std::string packPath = dir.file("bunny.hfa");
  Status s = packInput(*input, packPath, opt, nullptr, sum);
  ASSERT_TRUE(s.isOk()) << s.message();
  PackReader pack;
  ASSERT_TRUE(pack.open(packPath).isOk());
  auto mesh = loadMesh(test::sharedData("stanford_bunny/reconstruction/bun_zipper.ply"));
  ASSERT_TRUE(mesh.isOk()) << mesh.status().message();

  EglContext ctx;
  ASSERT_TRUE(ctx.init().isOk());
  Renderer r;
  ASSERT_TRUE(r.init(pack).isOk());
  // Cameras framed on the reference mesh's bounding box, about the pack's up (+y, Stanford's).
  ASSERT_NEAR(pack.up().y(), 1.0, 1e-12);
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (size_t i = 0; i < mesh->positions.size(); i += 3) {
    lo = lo.cwiseMin(Eigen::Vector3d(&mesh->positions[i]));
    hi = hi.cwiseMax(Eigen::Vector3d(&mesh->positions[i]));
  }
  const double diag = (hi - lo).norm();
  auto cams = orbitCameras(lo, hi, 8, pack.viewUp(), 40, 512, 512);
  double iouMin = 1;
  std::vector<double> depth, normal;
  RenderSettings rs;
  rs.useColor = false;
  for (size_t v = 0; v < cams.size(); ++v) {
    FrameResult fr;
    ASSERT_TRUE(r.render(cams[v], rs, fr, kReadColor | kReadDepth | kReadNormals).isOk());
    const ReferenceView ref = referenceView(*mesh, cams[v]);
    const ViewMetrics m = evaluateView(fr.color, fr.depth, fr.normals, ref, shadeReference(ref, cams[v], rs.baseColor, rs.background), diag);
    std::printf("bunny view %zu: IoU %.4f, depth error median %.5f%% of the diagonal, normal error median %.2f deg\n", v,
                m.iou, 100 * m.depthMedian, m.normalMedianDeg);
    iouMin = std::min(iouMin, m.iou);
    depth.insert(depth.end(), m.depthErrors.begin(), m.depthErrors.end());
    normal.insert(normal.end(), m.normalErrors.begin(), m.normalErrors.end());
  }
  const double depthMed = percentile(depth, 0.5), normalMed = percentile(normal, 0.5);
  std::printf("bunny: %u cells, worst IoU %.4f, median depth error %.5f%%, median normal error %.2f deg\n", sum.cells,
              iouMin, 100 * depthMed, normalMed);
  // Issue targets (at 1024^2; here 512^2): worst IoU >= 0.985, depth <= 3e-4 of the diagonal,
  // normals <= 7 degrees (the waffle pattern of unsmoothed merged scans gave 10.8).
  EXPECT_GE(iouMin, 0.985);
  EXPECT_LE(depthMed, 3e-4);
  EXPECT_LE(normalMed, 7.0);
}

// The bunny's raw scans packed in 14 chunks (--mem-budget 16M) against the same in one: the
// chunks' faces must not show. Before chunk halos each chunk fitted its points and made its
// cells' margins from its own points alone: along every face the fits were one-sided and the
// tiles did not meet, a line of dark dashes across the bunny's back (holes 99 -> 136, seam ratio
// 1.38 -> 1.53, depth p95 +1.9 % over `eval --orbit 8`).
TEST(Accuracy, BunnyScansInChunksMatchOneChunk) {
  ASSERT_TRUE(test::haveSharedData()) << "../shared/data is missing";
  test::TempDir dir;
  auto input = InputSet::open({test::sharedData("stanford_bunny/scans/bun.conf")});
  ASSERT_TRUE(input.isOk()) << input.status().message();
  auto mesh = loadMesh(test::sharedData("stanford_bunny/reconstruction/bun_zipper.ply"));
  ASSERT_TRUE(mesh.isOk()) << mesh.status().message();
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (size_t i = 0; i < mesh->positions.size(); i += 3) {
    lo = lo.cwiseMin(Eigen::Vector3d(&mesh->positions[i]));
    hi = hi.cwiseMax(Eigen::Vector3d(&mesh->positions[i]));
  }
  EglContext ctx;
  ASSERT_TRUE(ctx.init().isOk());
  MeshViews views[2];
  uint32_t chunks[2] = {0, 0};
  for (int k = 0; k < 2; ++k) {
    PackOptions opt;
    if (k == 1) opt.memBudget = 16u << 20;
    PackSummary sum;
    const std::string path = dir.file(k ? "chunks.hfa" : "one.hfa");
    ASSERT_TRUE(packInput(*input, path, opt, nullptr, sum).isOk());
    chunks[k] = sum.chunks;
    PackReader pack;
    ASSERT_TRUE(pack.open(path).isOk());
    Renderer r;
    ASSERT_TRUE(r.init(pack).isOk());
    views[k] = compareWithMesh(r, *mesh, orbitCameras(lo, hi, 8, pack.viewUp(), 40, 512, 512), (hi - lo).norm(),
                               k ? "bunny in chunks" : "bunny in one chunk");
  }
  EXPECT_EQ(chunks[0], 1u);
  EXPECT_GE(chunks[1], 8u);
  EXPECT_LE(double(views[1].holes), 1.2 * double(views[0].holes) + 4);
  EXPECT_LE(views[1].seamOrbit, 1.05 * views[0].seamOrbit);
  EXPECT_LE(views[1].depthP95Max, 1.01 * views[0].depthP95Max);
  EXPECT_GE(views[1].iouMin, views[0].iouMin - 0.0005);
}

// The reference-free measure (eval's "far"): every rendered surface pixel's distance to the
// nearest input point, in sample spacings (and in that point's own where it is wider), over
// orbit views about the pack's up axis.
FarStats farOverOrbit(const PackReader& pack, int views, int size) {
  EglContext ctx;
  EXPECT_TRUE(ctx.init().isOk());
  Renderer r;
  EXPECT_TRUE(r.init(pack).isOk());
  SourcePoints src;
  EXPECT_TRUE(loadSourcePoints(pack, src).isOk());
  const NearestSamples samples(std::move(src.xyz));
  const std::vector<float> area = samples.areaSpacings();
  Eigen::Vector3d lo, hi;
  const Eigen::Vector3d origin(pack.meta().origin);
  lo = origin + Eigen::Vector3d(pack.meta().boundsMin);
  hi = origin + Eigen::Vector3d(pack.meta().boundsMax);
  std::vector<double> all, local;
  for (const Camera& cam : orbitCameras(lo, hi, views, pack.viewUp(), 40, size, size)) {
    FrameResult fr;
    EXPECT_TRUE(r.render(cam, RenderSettings{}, fr, kReadDepth).isOk());
    const std::vector<double> hits = surfacePoints(cam, fr.depth, origin);
    std::vector<double> d(hits.size() / 3);
    std::vector<uint32_t> at(d.size());
    samples.distances(hits.data(), d.size(), d.data(), at.data());
    for (size_t i = 0; i < d.size(); ++i) {
      d[i] /= pack.meta().sampleSpacing;
      local.push_back(at[i] < area.size() ? std::max(1.0, area[at[i]] / pack.meta().sampleSpacing) : 1.0);
    }
    all.insert(all.end(), d.begin(), d.end());
  }
  return summarizeFar(all, &local);
}

// Aerial lidar, a terrestrial scan and a stereo camera's organized PCD: surface where no point
// is (walls from scan edges down to the box floor, interpolation across height jumps, skirts)
// made 11-23 % of autzen's pixels lie over 3 spacings from every point. Issue target: <= 1 %
// beyond 3 spacings, <= 0.1 % beyond 10.
class FarReal : public ::testing::TestWithParam<const char*> {};

TEST_P(FarReal, RenderedSurfaceLiesNearInputPoints) {
  ASSERT_TRUE(test::haveSharedData()) << "../shared/data is missing";
  test::TempDir dir;
  auto input = InputSet::open({test::sharedData(GetParam())});
  ASSERT_TRUE(input.isOk()) << input.status().message();
  PackSummary sum;
  ASSERT_TRUE(packInput(*input, dir.file("p.hfa"), PackOptions{}, nullptr, sum).isOk());
  PackReader pack;
  ASSERT_TRUE(pack.open(dir.file("p.hfa")).isOk());
  const FarStats f = farOverOrbit(pack, 8, 512);
  std::printf("%s: %zu surface pixels, median %.3f spacings, p99 %.3f, beyond 3: %.4f %%, beyond 10: %.4f %% "
              "(%u cells, up %.2f %.2f %.2f)\n",
              GetParam(), f.pixels, f.median, f.p99, 100 * f.beyond3, 100 * f.beyond10, sum.cells, sum.up.x(), sum.up.y(),
              sum.up.z());
  EXPECT_GT(f.pixels, 10000u);
  EXPECT_LE(f.beyond3, 0.01);
  EXPECT_LE(f.beyond10, 0.001);
  // --sparse-reach auto draws sparse surface (autzen's river) past 3 of the pack's spacings, but
  // not past 3 of the nearest point's own.
  PackOptions reach;
  reach.sparseReachAuto = true;
  ASSERT_TRUE(packInput(*input, dir.file("r.hfa"), reach, nullptr, sum).isOk());
  PackReader rp;
  ASSERT_TRUE(rp.open(dir.file("r.hfa")).isOk());
  const FarStats r = farOverOrbit(rp, 8, 512);
  std::printf("%s, --sparse-reach auto (%.2f): beyond 3 spacings %.4f %%, beyond 3 local spacings %.4f %% (default: %.4f %%)\n",
              GetParam(), sum.sparseReach, 100 * r.beyond3, 100 * r.beyond3Local, 100 * f.beyond3Local);
  EXPECT_GT(sum.sparseReach, 1.5);
  EXPECT_LE(r.beyond3Local, 0.001);
}

INSTANTIATE_TEST_SUITE_P(Scans, FarReal,
                         ::testing::Values("lidar/autzen_trim.las", "lidar/lone-star.las",
                                           "pcd/table_scene_mug_stereo_textured.pcd"));

}  // namespace
}  // namespace sa
