// The grooves mode on the GPU against the same grooves carved into a mesh and rendered exactly by
// the CPU reference (viewer/reference.h): a tilted plane packed without grooves, four grooves
// given (V and U profiles; two ending inside the view, four crossings) and stored as the GROO
// section; views where the grooves are about 20, 2 and 0.3 pixels wide. On groove pixels the
// depth must be within a quarter of the sample spacing (s = width / 3: the grooves are 3 samples
// wide), where parallax (the plane alone) is not; at 0.3 pixels the anti-aliased colour must match
// 16-sample supersampling of the carved mesh. The CPU cast (gcast::castGrooved) must agree with
// the shader.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>

#include "../common/pack_util.h"
#include "../common/render_util.h"
#include "grooves/grooves.h"
#include "modes/grooves/groove_bake.h"
#include "modes/grooves/groove_cast.h"
#include "modes/registry.h"
#include "viewer/reference.h"
#include "viewer/renderer.h"

namespace sa {
namespace {

// The plane: world = O + a U + b V + h N, (a, b) in [-1, 1]^2.
const Eigen::Vector3d kO(10.0, -4.0, 2.0);
const Eigen::Vector3d kN = Eigen::Vector3d(0.25, -0.2, 1.0).normalized();
const Eigen::Vector3d kU = Eigen::Vector3d::UnitX().cross(kN).cross(kN).normalized() * -1.0;
const Eigen::Vector3d kV = kN.cross(kU);

struct TestGroove {
  bool vertical;        // along b (at a = at), else along a (at b = at)
  double at, from, to;  // position, and extent along the groove
  bool rounded;
  double depthFactor;   // depth = factor x width
};

const TestGroove kGrooves[] = {
    {true, -0.30, -0.85, 0.85, false, 0.5},
    {true, 0.25, -0.85, 0.20, true, 0.4},   // ends inside the view
    {false, 0.35, -0.85, 0.85, false, 0.3},
    {false, -0.40, -0.55, 0.50, true, 0.6},  // ends on both sides, crosses both vertical grooves
};

// The profile as the 9 knots the section stores (depth at r = k / 8 half widths).
double knot(const TestGroove& g, double width, int k) {
  const double f = k / 8.0, d = g.depthFactor * width;
  return g.rounded ? d * std::sqrt(std::max(0.0, 1 - f * f)) : d * (1 - f);
}
double profileDepth(const TestGroove& g, double width, double r) {
  const double hw = width / 2;
  if (r >= hw) return 0;
  const double f = r / hw * 8;
  const int k = std::min(int(f), 7);
  return knot(g, width, k) + (knot(g, width, k + 1) - knot(g, width, k)) * (f - k);
}
double distanceTo(const TestGroove& g, double a, double b) {
  const double along = g.vertical ? b : a, across = g.vertical ? a - g.at : b - g.at;
  const double c = std::clamp(along, g.from, g.to);
  return std::hypot(across, along - c);
}
// The carved surface's height below the plane at (a, b), and whether (a, b) is in a groove.
double carved(double width, double a, double b, bool* inGroove = nullptr) {
  double d = 0;
  bool in = false;
  for (const TestGroove& g : kGrooves) {
    const double r = distanceTo(g, a, b);
    if (r < width / 2) in = true;
    d = std::max(d, profileDepth(g, width, r));
  }
  if (inGroove) *inGroove = in;
  return d;
}
Eigen::Vector3d world(double a, double b, double h) { return kO + a * kU + b * kV + h * kN; }

// Grid lines: coarse everywhere, dense (32 per half width, every profile knot among them) around
// every groove's centre line and its ends.
std::vector<double> lines(double width, bool alongA) {
  std::vector<double> v;
  for (int i = 0; i <= 64; ++i) v.push_back(-1 + 2.0 * i / 64);
  for (const TestGroove& g : kGrooves) {
    std::vector<double> centres;
    if (g.vertical == alongA) centres.push_back(g.at);  // a vertical groove's a lines
    else centres.insert(centres.end(), {g.from, g.to});  // its ends along the other axis
    for (double c : centres)
      for (int k = -40; k <= 40; ++k) v.push_back(c + k * (width / 2) / 32);
  }
  std::sort(v.begin(), v.end());
  v.erase(std::unique(v.begin(), v.end(), [](double x, double y) { return std::abs(x - y) < 1e-12; }), v.end());
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return x < -1 || x > 1; }), v.end());
  return v;
}

TriangleMesh carvedMesh(double width) {
  const std::vector<double> A = lines(width, true), B = lines(width, false);
  TriangleMesh m;
  for (double b : B)
    for (double a : A) {
      const Eigen::Vector3d p = world(a, b, -carved(width, a, b));
      m.positions.insert(m.positions.end(), {p.x(), p.y(), p.z()});
    }
  const uint32_t na = uint32_t(A.size());
  for (uint32_t j = 0; j + 1 < B.size(); ++j)
    for (uint32_t i = 0; i + 1 < na; ++i) {
      const uint32_t q = j * na + i;
      m.indices.insert(m.indices.end(), {q, q + 1, q + na + 1, q, q + na + 1, q + na});
    }
  return m;
}

void writePlanePly(const std::string& path) {
  std::ofstream o(path);
  const int n = 48;
  o << "ply\nformat ascii 1.0\nelement vertex " << (n + 1) * (n + 1)
    << "\nproperty double x\nproperty double y\nproperty double z\nproperty float nx\nproperty float ny\nproperty float nz\n"
    << "element face " << 2 * n * n << "\nproperty list uchar int vertex_indices\nend_header\n";
  o.precision(17);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const Eigen::Vector3d p = world(-1 + 2.0 * i / n, -1 + 2.0 * j / n, 0);
      o << p.x() << " " << p.y() << " " << p.z() << " " << kN.x() << " " << kN.y() << " " << kN.z() << "\n";
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int q = j * (n + 1) + i;
      o << "3 " << q << " " << q + 1 << " " << q + n + 2 << "\n3 " << q << " " << q + n + 2 << " " << q + n + 1 << "\n";
    }
}

GrooveSet givenGrooves(double width) {
  GrooveSet set;
  set.spacing = width / 3;
  for (const TestGroove& g : kGrooves) {
    Groove o;
    for (double t : {g.from, 0.5 * (g.from + g.to), g.to})
      o.line.push_back(g.vertical ? world(g.at, t, 0) : world(t, g.at, 0));
    o.width = width;
    o.depth = g.depthFactor * width;
    o.shape = g.rounded ? "U" : "V";
    o.length = g.to - g.from;
    for (int k = -8; k <= 8; ++k) o.profile.push_back({float(k / 8.0 * width / 2), float(-knot(g, width, std::abs(k)))});
    set.grooves.push_back(o);
  }
  return set;
}

// A camera looking at the plane's centre from 55 degrees off its normal.
Camera view(int size) {
  Camera c;
  c.target = world(0, 0, 0);
  c.eye = c.target + 2.6 * (std::cos(55 * M_PI / 180) * kN + std::sin(55 * M_PI / 180) * (0.6 * kU - 0.8 * kV).normalized());
  c.up = kN;
  c.fovDeg = 40;
  c.width = c.height = size;
  return c;
}

// The plane coordinates of the point at linear depth `depth` on pixel (x, y)'s ray.
Eigen::Vector2d planePoint(const Camera& cam, double x, double y, double depth) {
  const Eigen::Vector3d dir = cam.rayDirection(x, y);
  const Eigen::Vector3d p = cam.eye + dir * (depth / dir.dot(cam.forward())) - kO;
  return {p.dot(kU), p.dot(kV)};
}

double luminance(const uint8_t* p) { return (0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]) / 255.0; }

class GroovesGl : public test::GlTest {
 protected:
  // Packs the plane and stores the grooves of `width` (through a grooves JSON, as `pack
  // --grooves` does); returns the pack's path.
  std::string makePack(const test::TempDir& dir, double width) {
    writePlanePly(dir.file("plane.ply"));
    auto in = InputSet::open({dir.file("plane.ply")});
    EXPECT_TRUE(in.isOk());
    PackSummary sum;
    EXPECT_TRUE(packInput(*in, dir.file("plane.hfa"), PackOptions{}, nullptr, sum).isOk());
    EXPECT_TRUE(writeGroovesJson(givenGrooves(width), dir.file("given.json")).isOk());
    BakeRequest req;
    req.groovesFile = dir.file("given.json");
    std::vector<std::string> report;
    Status s = bakeModes(dir.file("plane.hfa"), dir.file("plane.hfa"), {RenderMode::kGrooves}, report, req);
    EXPECT_TRUE(s.isOk()) << s.message();
    for (const auto& r : report) std::printf("[grooves-gl] %s\n", r.c_str());
    return dir.file("plane.hfa");
  }

  // The plane with grooves of `width`, opened and uploaded.
  void openPlane(const test::TempDir& dir, double width, PackReader& p, Renderer& r) {
    ASSERT_TRUE(p.open(makePack(dir, width)).isOk());
    ASSERT_TRUE(r.init(p).isOk());
    ASSERT_TRUE(r.modeReady(RenderMode::kGrooves));
  }

  FrameResult render(Renderer& r, const Camera& cam, RenderMode mode, bool aa = true, bool boxes = false) {
    RenderSettings rs;
    rs.mode = mode;
    rs.grooveAA = aa;
    rs.showBoxes = boxes;
    FrameResult fr;
    Status s = r.render(cam, rs, fr, kReadColor | kReadDepth);
    EXPECT_TRUE(s.isOk()) << s.message();
    return fr;
  }

  // Over pixels whose reference point lies in a groove: the share within tol of the reference
  // depth (a coverage difference counts as outside).
  static double grooveAgreement(const Camera& cam, const std::vector<float>& ref, const std::vector<float>& test, double width,
                                double tol, size_t& pixels) {
    size_t ok = 0;
    pixels = 0;
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        const size_t i = size_t(y) * cam.width + x;
        if (!std::isfinite(ref[i])) continue;
        const Eigen::Vector2d q = planePoint(cam, x + 0.5, y + 0.5, ref[i]);
        bool in = false;
        carved(width, q.x(), q.y(), &in);
        if (!in || std::abs(q.x()) > 0.95 || std::abs(q.y()) > 0.95) continue;
        ++pixels;
        ok += std::isfinite(test[i]) && std::abs(double(test[i]) - ref[i]) <= tol;
      }
    return pixels ? double(ok) / double(pixels) : 0;
  }

  // The width that is `px` pixels on screen at the image centre.
  static double widthFor(const Camera& cam, double px) {
    return px * (cam.target - cam.eye).norm() * cam.fovDeg * M_PI / 180 / cam.height;
  }

  // Width of the grooves on screen at the image centre, in pixels.
  static double widthPixels(const Camera& cam, double width) {
    const double dist = (cam.target - cam.eye).norm();
    return width / (dist * cam.fovDeg * M_PI / 180 / cam.height);
  }
};

TEST_F(GroovesGl, DepthMatchesTheCarvedMeshAt20And2And03Pixels) {
  const Camera cam = view(256);
  for (double px : {20.0, 2.0, 0.3}) {
    const double width = widthFor(cam, px);
    test::TempDir dir;
    PackReader p;
    Renderer r;
    ASSERT_NO_FATAL_FAILURE(openPlane(dir, width, p, r));
    const TriangleMesh mesh = carvedMesh(width);
    const std::vector<float> ref = referenceDepth(mesh, cam);
    const FrameResult g = render(r, cam, RenderMode::kGrooves), par = render(r, cam, RenderMode::kParallax);
    const double s = width / 3, tol = 0.25 * s;
    size_t n = 0;
    const double agree = grooveAgreement(cam, ref, g.depth, width, tol, n);
    const double agreeParallax = grooveAgreement(cam, ref, par.depth, width, tol, n);
    std::printf("[grooves-gl] %.1f px wide (%.2f at the centre): %zu groove pixels, within 0.25 s: grooves %.4f, parallax %.4f\n", px,
                widthPixels(cam, width), n, agree, agreeParallax);
    EXPECT_GT(n, px > 10 ? 5000u : px > 1 ? 500u : 80u);
    EXPECT_GE(agree, 0.99) << px << " px";
    // The carved cast ran only where the first pass deferred (near the grooves), and every such
    // pixel found a slot.
    std::printf("[grooves-gl] %.1f px: %llu pixels deferred to the carved cast, %llu without a slot\n", px,
                (unsigned long long)g.stats.deferred, (unsigned long long)g.stats.undeferred);
    EXPECT_GE(g.stats.deferred, n / 2);
    EXPECT_EQ(g.stats.undeferred, 0u);
    // The plane alone is not the carved surface: the grooves are really drawn.
    if (px > 1) {
      EXPECT_LT(agreeParallax, 0.5) << px << " px";
    }
  }
}

// Self-shadowing (every hit of a cell with grooves then takes the carved cast, and its shadow ray
// the carved surface): a light low across the two grooves that run along b shades their floors
// near the wall it comes over. Against the carved surface's own shadows (the analytic profile,
// marched toward the light) the flags agree; parallax (the plane alone) has none.
TEST_F(GroovesGl, ShadowsFallInsideTheGroovesAsOnTheCarvedSurface) {
  const Camera cam = view(256);
  const double width = widthFor(cam, 20);
  test::TempDir dir;
  PackReader p;
  Renderer r;
  ASSERT_NO_FATAL_FAILURE(openPlane(dir, width, p, r));
  RenderSettings rs;
  rs.shadows = true;
  rs.headLight = false;
  const double elevation = 25 * M_PI / 180;
  rs.lightDir = std::cos(elevation) * kU + std::sin(elevation) * kN;
  const Eigen::Vector3d l(rs.lightDir.dot(kU), rs.lightDir.dot(kV), rs.lightDir.dot(kN));
  FrameResult fr[2];
  for (int k = 0; k < 2; ++k) {
    rs.mode = k ? RenderMode::kParallax : RenderMode::kGrooves;
    Status s = r.render(cam, rs, fr[k], kReadDepth | kReadShadow);
    ASSERT_TRUE(s.isOk()) << s.message();
  }
  size_t groove = 0, agree = 0, shadowed = 0, cpuShadowed = 0, parallaxShadowed = 0, plane = 0, planeShadowed = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const size_t i = size_t(y) * cam.width + x;
      if (!std::isfinite(fr[0].depth[i])) continue;
      const Eigen::Vector2d q = planePoint(cam, x + 0.5, y + 0.5, fr[0].depth[i]);
      if (std::abs(q.x()) > 0.9 || std::abs(q.y()) > 0.9) continue;
      bool in = false;
      const double h = -carved(width, q.x(), q.y(), &in);
      if (!in) {
        double gapToGroove = 1e9;
        for (const TestGroove& g : kGrooves) gapToGroove = std::min(gapToGroove, distanceTo(g, q.x(), q.y()) - width / 2);
        if (gapToGroove > width / 4) {
          ++plane;
          planeShadowed += fr[0].shadowed[i];
        }
        continue;
      }
      // The carved surface's shadow: marched from the point toward the light until above the plane.
      bool cpu = false;
      for (double t = width / 400; h + t * l.z() < 0 && !cpu; t += width / 400)
        cpu = h + t * l.z() < -carved(width, q.x() + t * l.x(), q.y() + t * l.y()) - 1e-4 * width;
      ++groove;
      shadowed += fr[0].shadowed[i];
      cpuShadowed += cpu;
      parallaxShadowed += fr[1].shadowed[i];
      agree += bool(fr[0].shadowed[i]) == cpu;
    }
  std::printf("[grooves-gl] shadows: %zu groove pixels, %zu shadowed (carved surface: %zu, parallax: %zu), %.4f agree; "
              "%zu of %zu plane pixels shadowed\n",
              groove, shadowed, cpuShadowed, parallaxShadowed, double(agree) / double(std::max<size_t>(groove, 1)), planeShadowed, plane);
  EXPECT_GT(groove, 5000u);
  EXPECT_GT(cpuShadowed, groove / 20);
  EXPECT_GE(double(agree), 0.97 * double(groove));
  EXPECT_EQ(parallaxShadowed, 0u);
  EXPECT_LE(double(planeShadowed), 0.001 * double(plane));
}

TEST_F(GroovesGl, NarrowGroovesAreAntiAliasedLikeSupersampling) {
  const Camera cam = view(192);
  const double width = widthFor(cam, 0.3);
  test::TempDir dir;
  PackReader p;
  Renderer r;
  ASSERT_NO_FATAL_FAILURE(openPlane(dir, width, p, r));
  const FrameResult aa = render(r, cam, RenderMode::kGrooves, true), one = render(r, cam, RenderMode::kGrooves, false);
  // 16 samples a pixel (4 x 4) of the carved mesh, shaded as the viewer shades.
  Camera big = cam;
  big.width = big.height = cam.width * 4;
  const TriangleMesh mesh = carvedMesh(width);
  const ReferenceView rv = referenceView(mesh, big);
  RenderSettings rs;
  const Image shaded = shadeReference(rv, big, rs.baseColor, rs.background);
  double errAA = 0, errOne = 0;
  size_t n = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      double lum = 0;
      bool groove = false, all = true;
      for (int k = 0; k < 16; ++k) {
        const int bx = 4 * x + (k & 3), by = 4 * y + (k >> 2);
        const size_t bi = size_t(by) * big.width + bx;
        lum += luminance(&shaded.rgba[4 * bi]) / 16;
        if (!std::isfinite(rv.depth[bi])) {
          all = false;
          continue;
        }
        const Eigen::Vector2d q = planePoint(big, bx + 0.5, by + 0.5, rv.depth[bi]);
        bool in = false;
        carved(width, q.x(), q.y(), &in);
        groove = groove || in;
        all = all && std::abs(q.x()) < 0.95 && std::abs(q.y()) < 0.95;
      }
      if (!groove || !all) continue;
      const size_t i = size_t(y) * cam.width + x;
      errAA += std::abs(luminance(&aa.color.rgba[4 * i]) - lum);
      errOne += std::abs(luminance(&one.color.rgba[4 * i]) - lum);
      ++n;
    }
  ASSERT_GT(n, 300u);
  errAA /= double(n);
  errOne /= double(n);
  std::printf("[grooves-gl] 0.3 px grooves, %zu pixels: mean luminance error against 16 samples: anti-aliased %.4f, one ray %.4f\n", n,
              errAA, errOne);
  EXPECT_LE(errAA, 0.02);
  EXPECT_LT(errAA, 0.6 * errOne);  // the footprint integration is what brings it there
}

TEST_F(GroovesGl, CpuCastAgreesWithTheShader) {
  const Camera cam = view(128);
  const double width = widthFor(cam, 12);
  test::TempDir dir;
  PackReader p;
  ASSERT_TRUE(p.open(makePack(dir, width)).isOk());
  auto sec = gcast::readSection(p);
  ASSERT_TRUE(sec.isOk() && sec->present);
  const gcast::Model m = gcast::modelFromSection(p, *sec);
  ASSERT_EQ(m.grooves, 4u);
  Renderer r;
  ASSERT_TRUE(r.init(p).isOk());
  const FrameResult g = render(r, cam, RenderMode::kGrooves);
  const Eigen::Vector3d origin(p.meta().origin);
  size_t both = 0, agree = 0, coverage = 0, floors = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Eigen::Vector3d dir = cam.rayDirection(x + 0.5, y + 0.5);
      double best = INFINITY;
      int piece = -1;
      for (uint32_t ci = 0; ci < p.cells().size(); ++ci) {
        const CellRecord& c = p.cells()[ci];
        const Eigen::Vector3d U(c.u), V(c.v), W(c.w), rel = cam.eye - origin - Eigen::Vector3d(c.origin);
        const Eigen::Vector3d o(rel.dot(U), rel.dot(V), rel.dot(W)), d(dir.dot(U), dir.dot(V), dir.dot(W));
        double box[6];
        std::copy(c.box, c.box + 6, box);
        if (const gcast::CellPieces* cp = m.find(ci)) box[4] = std::min(box[4], cp->floor);  // grooves cut below the box
        double t0 = 0, t1 = INFINITY;
        for (int k = 0; k < 3; ++k) {
          const double a = (box[2 * k] - o[k]) / d[k], b = (box[2 * k + 1] - o[k]) / d[k];
          t0 = std::max(t0, std::min(a, b));
          t1 = std::min(t1, std::max(a, b));
        }
        if (!(t0 < t1)) continue;
        gcast::CastResult cr;
        if (gcast::castGrooved(p, c, m, ci, o, d, t0, t1, cr) && cr.t < best) best = cr.t, piece = cr.piece;
      }
      const size_t i = size_t(y) * cam.width + x;
      const bool cc = std::isfinite(best), gc = std::isfinite(g.depth[i]);
      if (cc != gc) {
        ++coverage;
        continue;
      }
      if (!cc) continue;
      ++both;
      floors += piece >= 0;
      agree += std::abs(best * dir.dot(cam.forward()) - g.depth[i]) <= 0.02 * width;
    }
  std::printf("[grooves-gl] CPU cast vs shader: %zu pixels (%zu on groove floors), %.4f within 2 %% of the width, %zu coverage differences\n",
              both, floors, both ? double(agree) / both : 0.0, coverage);
  EXPECT_GT(floors, 500u);
  EXPECT_GE(double(agree) / double(both), 0.995);
  EXPECT_LE(coverage, 4u);
}

}  // namespace
}  // namespace sa

namespace sa {
namespace {

// Distance from world point w to the groove's centre line.
double lineDistance(const Groove& g, const Eigen::Vector3d& w) {
  double best = INFINITY;
  for (size_t k = 0; k + 1 < g.line.size(); ++k) {
    const Eigen::Vector3d a = g.line[k], ab = g.line[k + 1] - a;
    const double f = ab.squaredNorm() > 0 ? std::clamp((w - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 0.0;
    best = std::min(best, (a + ab * f - w).norm());
  }
  return best;
}

// A real scan: Igea's carving, its grooves detected in the raw points by the bake. Away from every
// groove the image is parallax's (up to float rounding: a groove neither detected nor given is never drawn);
// on them the carved floors change the depth.
TEST_F(GroovesGl, RealScanGroovesDrawOnlyWhereDetected) {
  test::TempDir dir;
  PackReader p0;
  ASSERT_TRUE(test::packShared(dir, "igea/igea.ply", p0, "igea").isOk());
  const std::string path = dir.file("igea.hfa");
  std::vector<std::string> report;
  Status s = bakeModes(path, path, {RenderMode::kGrooves}, report);
  ASSERT_TRUE(s.isOk()) << s.message();
  for (const auto& r : report) std::printf("[grooves-gl] igea: %s\n", r.c_str());
  PackReader p;
  ASSERT_TRUE(p.open(path).isOk());
  auto set = grooves::packGrooves(p);
  ASSERT_TRUE(set.isOk()) << set.status().message();
  ASSERT_GT(set->grooves.size(), 0u) << "igea's carving has grooves the detection finds (docs/BENCHMARKS.md)";
  Renderer r;
  ASSERT_TRUE(r.init(p).isOk());
  ASSERT_TRUE(r.modeReady(RenderMode::kGrooves));
  const Eigen::Vector3d origin(p.meta().origin);
  const Eigen::Vector3d lo = Eigen::Vector3d(p.meta().boundsMin) + origin, hi = Eigen::Vector3d(p.meta().boundsMax) + origin;
  size_t far = 0, farSame = 0, near = 0, nearChanged = 0, sameDepth = 0, edgesApart = 0;
  double maxWidth = 0;
  for (const Groove& g : set->grooves) maxWidth = std::max(maxWidth, g.width);
  const double margin = 4 * p.meta().sampleSpacing + maxWidth;
  uint64_t deferred = 0, undeferred = 0;
  for (const Camera& cam : orbitCameras(lo, hi, 4, p.viewUp(), 40, 256, 256)) {
    const FrameResult g = render(r, cam, RenderMode::kGrooves), par = render(r, cam, RenderMode::kParallax);
    deferred += g.stats.deferred;
    undeferred += g.stats.undeferred;
    // The decomposition view's box edges are depth-tested against the surface: where the grooves'
    // surface is parallax's, the same edges show (the second pass writes the linear depth, and the
    // depth buffer is rebuilt from it before the edges).
    const FrameResult gb = render(r, cam, RenderMode::kGrooves, true, true), pb = render(r, cam, RenderMode::kParallax, true, true);
    for (size_t i = 0; i < g.depth.size(); ++i) {
      if (!(std::abs(g.depth[i] - par.depth[i]) <= 1e-6f * par.depth[i])) continue;
      ++sameDepth;
      const bool edgeG = std::memcmp(&gb.color.rgba[4 * i], &g.color.rgba[4 * i], 3) != 0;
      const bool edgeP = std::memcmp(&pb.color.rgba[4 * i], &par.color.rgba[4 * i], 3) != 0;
      edgesApart += edgeG != edgeP;
    }
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        const size_t i = size_t(y) * cam.width + x;
        if (!std::isfinite(par.depth[i])) continue;
        const Eigen::Vector3d dir = cam.rayDirection(x + 0.5, y + 0.5);
        const Eigen::Vector3d w = cam.eye + dir * (par.depth[i] / dir.dot(cam.forward()));
        double dist = INFINITY;
        for (const Groove& gr : set->grooves) dist = std::min(dist, lineDistance(gr, w) - gr.width / 2);
        // Beyond the anti-aliasing's reach too (0.75 pixel footprints over the incidence's cosine,
        // at most 1/0.1: grooves.glsl gFootprintReach).
        const double footprint = (w - cam.eye).norm() * cam.fovDeg * M_PI / 180 / cam.height;
        if (dist > margin + 7.5 * footprint) {
          ++far;
          // The same march compiled into another program: equal up to float rounding.
          bool same = std::abs(g.depth[i] - par.depth[i]) <= 1e-6f * par.depth[i];
          for (int k = 0; k < 3; ++k) same = same && std::abs(int(g.color.rgba[4 * i + k]) - int(par.color.rgba[4 * i + k])) <= 1;
          farSame += same;
        } else if (dist < 0) {
          ++near;
          nearChanged += !(std::abs(g.depth[i] - par.depth[i]) < 1e-6f * par.depth[i]);
        }
      }
  }
  std::printf("[grooves-gl] igea: %zu pixels away from the grooves, %zu the same as parallax; %zu on them, %zu changed\n", far,
              farSame, near, nearChanged);
  // Where several cells' boxes with grooves overlap on a pixel (27 of them here), a fifth cell
  // finds no slot and draws its height field there: 42 of 17653 pixels (with 3 slots a pixel,
  // 200 of 17495).
  std::printf("[grooves-gl] igea: %llu pixels deferred to the carved cast, %llu without a slot\n", (unsigned long long)deferred,
              (unsigned long long)undeferred);
  EXPECT_GT(deferred, 1000u);
  EXPECT_LE(double(undeferred), 0.005 * double(deferred));
  EXPECT_GT(far, 10000u);
  EXPECT_GE(double(farSame), 0.999 * double(far));
  EXPECT_GT(nearChanged, 0u);
  std::printf("[grooves-gl] igea --boxes: %zu of %zu pixels where grooves' depth is parallax's show a box edge in one mode only\n",
              edgesApart, sameDepth);
  EXPECT_GT(sameDepth, 10000u);
  EXPECT_LE(double(edgesApart), 1e-4 * double(sameDepth));
}

// A section of an older version (1: tangent-plane rims) is not misread and does not stop the pack
// from drawing: the grooves mode falls back to parallax with the reason, the other modes draw.
TEST_F(GroovesGl, AnOlderSectionFallsBackWithTheReason) {
  test::TempDir dir;
  PackReader p;
  ASSERT_TRUE(p.open(makePack(dir, 0.05)).isOk());
  ExtraSection old;
  std::memcpy(old.id, gcast::kSectionId, 4);
  const auto bytes = p.section(gcast::kSectionId);
  old.bytes.assign(bytes.begin(), bytes.end());
  ASSERT_GE(old.bytes.size(), 4u);
  old.bytes[0] = 1;  // the header's version
  ASSERT_TRUE(rewritePackWithSections(p, dir.file("old.hfa"), {old}).isOk());
  PackReader q;
  ASSERT_TRUE(q.open(dir.file("old.hfa")).isOk());
  Renderer r;
  Status s = r.init(q);
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_FALSE(r.modeReady(RenderMode::kGrooves));
  EXPECT_EQ(r.drawnMode(RenderMode::kGrooves), RenderMode::kParallax);
  EXPECT_NE(r.modeProblem(RenderMode::kGrooves).find("version 1"), std::string::npos) << r.modeProblem(RenderMode::kGrooves);
  EXPECT_NE(modeSection(q, RenderMode::kGrooves).problem.find("bake it again"), std::string::npos);
  const FrameResult f = render(r, view(64), RenderMode::kParallax);
  EXPECT_GT(std::count_if(f.depth.begin(), f.depth.end(), [](float d) { return std::isfinite(d); }), 1000);
}

}  // namespace
}  // namespace sa
