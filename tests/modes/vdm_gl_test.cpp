// The vdm mode on the GPU (modes/vdm/vdm.glsl) against the exact CPU reference, beside
// parallax-12 in the same run: 8 orbit views at 512x512 and grazing views of a bumpy plane with
// holes, every cell baked. Agreement within half a texel, IoU, and the fallbacks counted by the
// shader (top-face lookups that went to the exact traversal).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "../common/render_util.h"
#include "modes/exact/exact.h"
#include "modes/registry.h"
#include "viewer/renderer.h"

namespace sa {
namespace {

class VdmGl : public test::GlTest {
 protected:
  // Self-shadowing: lit / shadowed per pixel from the vdm (and exact) shader against a CPU shadow
  // ray (the exact traversal from the CPU hit toward the light, within the hit's cell), at light
  // elevations 45 and 70 degrees.
  void checkShadows(const PackReader& p, Renderer& r, const Camera& cam) {
    CpuRaycaster rc(p);
    const Eigen::Vector3d origin(p.meta().origin);
    for (double elev : {45.0, 70.0}) {
      const double e = elev * M_PI / 180, az = 0.7;
      const Eigen::Vector3d light(std::cos(e) * std::cos(az), std::cos(e) * std::sin(az), std::sin(e));
      RenderSettings rs;
      rs.cull.subpixelSplats = false;
      rs.headLight = false;
      rs.lightDir = light;
      rs.shadows = true;
      for (RenderMode m : {RenderMode::kVdm, RenderMode::kExact}) {
        rs.mode = m;
        FrameResult fr;
        ASSERT_TRUE(r.render(cam, rs, fr, kReadDepth | kReadShadow).isOk());
        size_t both = 0, agree = 0, shadowed = 0;
        for (int y = 0; y < cam.height; ++y)
          for (int x = 0; x < cam.width; ++x) {
            const size_t i = size_t(y) * cam.width + x;
            if (!std::isfinite(fr.depth[i])) continue;
            const Eigen::Vector3d dir = cam.rayDirection(x + 0.5, y + 0.5);
            const RayHit h = rc.cast(cam.eye - origin, dir);
            if (!h.hit || std::abs(h.t * dir.dot(cam.forward()) - fr.depth[i]) > 0.5 * p.meta().texelSize) continue;
            const CellRecord& c = p.cells()[h.cell];
            const Eigen::Vector3d U(c.u), V(c.v), W(c.w), rel = cam.eye - origin + dir * h.t - Eigen::Vector3d(c.origin);
            const Eigen::Vector3d l(light.dot(U), light.dot(V), light.dot(W));
            const double texel = std::min((c.box[1] - c.box[0]) / c.tileW, (c.box[3] - c.box[2]) / c.tileH);
            const Eigen::Vector3d q(rel.dot(U), rel.dot(V), rel.dot(W) + 0.05 * texel);
            bool cpuShadow = l.z() <= 0;
            if (!cpuShadow) {
              double t1 = 1e300;
              for (int a = 0; a < 3; ++a)
                if (l[a] != 0) t1 = std::min(t1, std::max((c.box[2 * a] - q[a]) / l[a], (c.box[2 * a + 1] - q[a]) / l[a]));
              std::vector<uint16_t> pyr;
              if (pyrCell_ != h.cell) {
                pyr_.clear();
                exact::buildCellPyramid(p, c, pyr_);
                pyrCell_ = h.cell;
              }
              double t;
              cpuShadow = t1 > 0 && exact::traceCell(p, c, pyr_.data(), q, l.normalized(), 0, t1, t);
            }
            ++both;
            shadowed += cpuShadow;
            agree += cpuShadow == bool(fr.shadowed[i]);
          }
        std::printf("[vdm-gl] shadows, light %.0f deg up, %s: %zu pixels (%.1f%% in shadow), lit/shadowed agree %.2f%%\n", elev,
                    modeName(m), both, 100.0 * double(shadowed) / double(std::max<size_t>(both, 1)),
                    100.0 * double(agree) / double(std::max<size_t>(both, 1)));
        EXPECT_GT(both, 10000u);
        EXPECT_GT(shadowed, both / 100) << "the scene must cast shadows at this light";
        EXPECT_GE(double(agree), 0.95 * double(both)) << modeName(m) << " at " << elev;
      }
    }
  }
  std::vector<uint16_t> pyr_;
  uint32_t pyrCell_ = UINT32_MAX;
};

double iou(const std::vector<float>& a, const std::vector<float>& b) {
  size_t inter = 0, uni = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    const bool x = std::isfinite(a[i]), y = std::isfinite(b[i]);
    inter += x && y;
    uni += x || y;
  }
  return uni ? double(inter) / double(uni) : 1.0;
}

TEST_F(VdmGl, OrbitAndGrazingViewsAgainstTheExactReferenceBesideParallax12) {
  test::TempDir dir;
  std::vector<Eigen::Vector3d> pts, nrm;
  const int n = 240;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double x = -1 + 2.0 * i / (n - 1), y = -1 + 2.0 * j / (n - 1);
      if (std::pow(x - 0.3, 2) + std::pow(y + 0.2, 2) < 0.04 || std::abs(x + 0.4) < 0.03) continue;  // a hole, a slot
      const double z = 0.08 * std::sin(5 * x) * std::cos(4 * y);
      pts.emplace_back(x, y, z);
      nrm.push_back(Eigen::Vector3d(-0.4 * std::cos(5 * x) * std::cos(4 * y), 0.32 * std::sin(5 * x) * std::sin(4 * y), 1).normalized());
    }
  PackOptions opt;
  opt.texelSize = 2.0 / 128;  // 128 x 128 texels: a bake of seconds
  const std::string pack = test::packPoints(dir, pts, nrm, "plane", opt);
  std::vector<std::string> report;
  BakeRequest req;
  req.budget = uint64_t(1) << 30;
  ASSERT_TRUE(bakeModes(pack, pack, {RenderMode::kVdm}, report, req).isOk());
  for (const auto& r : report) std::printf("[vdm-gl] %s\n", r.c_str());
  PackReader p;
  ASSERT_TRUE(p.open(pack).isOk());
  Renderer r;
  ASSERT_TRUE(r.init(p).isOk());
  ASSERT_TRUE(r.modeReady(RenderMode::kVdm));
  std::vector<Camera> cams = orbitCameras(Eigen::Vector3d(-1, -1, -0.1), Eigen::Vector3d(1, 1, 0.1), 8, Eigen::Vector3d::UnitZ(), 40, 512, 512);
  for (Camera& c : cams) c.eye = c.target + (c.eye - c.target).normalized() * 3.0 + Eigen::Vector3d(0, 0, 1.5);
  for (double deg : {60.0, 80.0, 85.0, 89.0}) {
    const double a = deg * M_PI / 180;
    Camera cam;
    cam.target = Eigen::Vector3d::Zero();
    cam.eye = 3.0 * Eigen::Vector3d(std::sin(a), 0.1 * std::sin(a), std::cos(a)).normalized();
    cam.up = Eigen::Vector3d::UnitZ();
    cam.width = cam.height = 256;
    cam.fovDeg = 30;
    cams.push_back(cam);
  }
  const double texel = p.meta().texelSize;
  size_t covV = 0, agreeV = 0, covP = 0, agreeP = 0;
  double iouV = 0, iouP = 0;
  WorkCounters work;
  for (size_t v = 0; v < cams.size(); ++v) {
    const auto ref = test::cpuDepth(p, cams[v]);
    RenderSettings rs;
    rs.cull.subpixelSplats = false;
    rs.mode = RenderMode::kVdm;
    rs.countWork = true;
    FrameResult fv, fp;
    ASSERT_TRUE(r.render(cams[v], rs, fv, true).isOk());
    ASSERT_EQ(fv.stats.drawnMode, RenderMode::kVdm);
    work.add(fv.stats.work);
    rs.mode = RenderMode::kParallax;
    rs.iterations = 12;
    rs.countWork = false;
    ASSERT_TRUE(r.render(cams[v], rs, fp, true).isOk());
    const test::Agreement av = test::agreement(fv.depth, ref, 0.5 * texel), ap = test::agreement(fp.depth, ref, 0.5 * texel);
    covV += av.covered;
    agreeV += av.agree;
    covP += ap.covered;
    agreeP += ap.agree;
    iouV += iou(fv.depth, ref) / double(cams.size());
    iouP += iou(fp.depth, ref) / double(cams.size());
    std::printf("[vdm-gl] view %2zu: within 0.5 texel vdm %.3f%% parallax-12 %.3f%%, IoU vdm %.5f parallax-12 %.5f\n", v,
                100.0 * double(av.agree) / double(std::max<size_t>(av.covered, 1)),
                100.0 * double(ap.agree) / double(std::max<size_t>(ap.covered, 1)), iou(fv.depth, ref), iou(fp.depth, ref));
  }
  const double fb = work.lookups ? double(work.fallbacks) / double(work.lookups) : 1.0;
  std::printf("[vdm-gl] all views: within 0.5 texel vdm %.3f%% parallax-12 %.3f%%; IoU vdm %.5f parallax-12 %.5f; top-face "
              "lookups %llu, fallbacks %.1f%%, fast misses %.1f%%\n",
              100.0 * double(agreeV) / double(covV), 100.0 * double(agreeP) / double(covP), iouV, iouP,
              (unsigned long long)work.lookups, 100 * fb, 100.0 * double(work.fastMisses) / double(std::max<uint64_t>(work.lookups, 1)));
  EXPECT_GT(work.lookups, 100000u);
  EXPECT_GE(double(agreeV) / double(covV), double(agreeP) / double(covP));
  EXPECT_GE(iouV, iouP - 0.002);
  EXPECT_LE(fb, 0.35);
}

// Steep bumps (slopes up to 77 degrees) cast shadows at both light elevations.
TEST_F(VdmGl, SelfShadowsAgreeWithCpuShadowRays) {
  test::TempDir dir;
  std::vector<Eigen::Vector3d> pts, nrm;
  const int n = 240;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double x = -1 + 2.0 * i / (n - 1), y = -1 + 2.0 * j / (n - 1);
      const double z = 0.3 * std::sin(13 * x) * std::cos(13 * y);
      pts.emplace_back(x, y, z);
      nrm.push_back(Eigen::Vector3d(-3.9 * std::cos(13 * x) * std::cos(13 * y), 3.9 * std::sin(13 * x) * std::sin(13 * y), 1).normalized());
    }
  PackOptions opt;
  opt.texelSize = 2.0 / 128;
  const std::string pack = test::packPoints(dir, pts, nrm, "steep", opt);
  std::vector<std::string> report;
  BakeRequest req;
  req.budget = uint64_t(1) << 30;
  ASSERT_TRUE(bakeModes(pack, pack, {RenderMode::kVdm}, report, req).isOk());
  PackReader p;
  ASSERT_TRUE(p.open(pack).isOk());
  Renderer r;
  ASSERT_TRUE(r.init(p).isOk());
  ASSERT_TRUE(r.modeReady(RenderMode::kVdm));
  std::printf("[vdm-gl] steep bumps: %zu cells\n", p.cells().size());
  Camera cam;
  cam.target = Eigen::Vector3d::Zero();
  cam.eye = Eigen::Vector3d(0.4, -1.2, 2.2);
  cam.up = Eigen::Vector3d::UnitZ();
  cam.width = cam.height = 256;
  cam.fovDeg = 50;
  checkShadows(p, r, cam);
}

}  // namespace
}  // namespace sa
