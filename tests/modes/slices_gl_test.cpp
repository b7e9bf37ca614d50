// The slices mode on the GPU (modes/slices/): a bumpy height field seen at 60, 80 and 89 degrees
// from its normal, against the double-precision CPU cast (the exact surface every mode draws):
// depth within sqrt(3) times the slices' spacing along the view plus half a texel (004 §4.1's
// bound, with the spacing measured along the view: a flat cell's w slices are close together
// but meet a grazing view obliquely) on 99 % of the pixels both cover, the error shrinking as
// slices are added, and at 32 slices the coverage of parallax-12 (IoU within 0.005); fragments growing with the slice count (a
// single ray-marched quad would not); and at 85 degrees the per-cell axis switch keeping the
// depth close where slicing along w alone meets the view with slices far apart along it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "../common/render_util.h"
#include "modes/registry.h"
#include "viewer/renderer.h"

namespace sa {
namespace {

class SlicesGl : public test::GlTest {
 protected:
  void SetUp() override {
    std::vector<Eigen::Vector3d> pts, nrm;
    const int n = 200;
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double x = -1 + 2.0 * i / (n - 1), y = -1 + 2.0 * j / (n - 1), amp = 0.08;
        pts.emplace_back(x, y, amp * std::sin(3 * x) * std::cos(2 * y));
        nrm.push_back(Eigen::Vector3d(-amp * 3 * std::cos(3 * x) * std::cos(2 * y), amp * 2 * std::sin(3 * x) * std::sin(2 * y), 1)
                          .normalized());
      }
    path_ = test::packPoints(dir_, pts, nrm, "plane");
    ASSERT_TRUE(pack_.open(path_).isOk());
    ASSERT_EQ(pack_.cells().size(), 1u);
    ASSERT_TRUE(r_.init(pack_).isOk());
    ASSERT_TRUE(r_.modeReady(RenderMode::kSlices));
  }

  Camera view(double deg) const {
    const double a = deg * M_PI / 180;
    Camera cam;
    cam.target = Eigen::Vector3d(0, 0, 0);
    cam.eye = cam.target + 3.0 * Eigen::Vector3d(std::sin(a), 0.3 * std::sin(a), std::cos(a)).normalized();
    cam.up = Eigen::Vector3d::UnitZ();
    cam.width = cam.height = 128;
    cam.fovDeg = 40;
    return cam;
  }

  // How far apart along the view's rays the slices slices_vs.glsl draws for this view lie: the
  // axis a with the largest |d_a| / extent_a (d: toward the box centre), spacing
  // extent_a / (n - 1) over |r_a|, the largest over the rays through the image's corners and centre.
  double alongView(const Camera& cam, int n, int forceAxis = -1) const {
    const CellRecord& c = pack_.cells()[0];
    const Eigen::Vector3d U(c.u), V(c.v), W(c.w);
    const Eigen::Vector3d rel = cam.eye - Eigen::Vector3d(pack_.meta().origin) - Eigen::Vector3d(c.origin);
    const Eigen::Vector3d camF(rel.dot(U), rel.dot(V), rel.dot(W));
    const Eigen::Vector3d lo(c.box[0], c.box[2], c.box[4]), hi(c.box[1], c.box[3], c.box[5]);
    const Eigen::Vector3d d = (0.5 * (lo + hi) - camF).normalized().cwiseAbs(), r = d.cwiseQuotient(hi - lo);
    int a = forceAxis;
    if (a < 0) a = r.x() >= r.y() && r.x() >= r.z() ? 0 : (r.y() >= r.z() ? 1 : 2);
    double worst = 0;
    for (const auto& px : {Eigen::Vector2d(0, 0), Eigen::Vector2d(cam.width, 0), Eigen::Vector2d(0, cam.height),
                           Eigen::Vector2d(cam.width, cam.height), Eigen::Vector2d(cam.width / 2.0, cam.height / 2.0)}) {
      const Eigen::Vector3d ray = cam.rayDirection(px.x(), px.y());
      const double ra = std::abs(Eigen::Vector3d(ray.dot(U), ray.dot(V), ray.dot(W))[a]);
      worst = std::max(worst, (hi[a] - lo[a]) / std::max(n - 1, 1) / std::max(ra, 1e-9));
    }
    return worst;
  }

  FrameResult render(const Camera& cam, int n, int axis = -1) {
    RenderSettings rs;
    rs.mode = RenderMode::kSlices;
    rs.slices = n;
    rs.sliceAxis = axis;
    rs.cull.subpixelSplats = false;
    FrameResult fr;
    const Status s = r_.render(cam, rs, fr, kReadDepth);
    EXPECT_TRUE(s.isOk()) << s.message();
    EXPECT_EQ(fr.stats.drawnMode, RenderMode::kSlices);
    return fr;
  }

  double texel() const {
    const CellRecord& c = pack_.cells()[0];
    return std::max((c.box[1] - c.box[0]) / c.tileW, (c.box[3] - c.box[2]) / c.tileH);
  }

  // Pixel coverage IoU of a render against the CPU reference.
  static double iou(const std::vector<float>& gpu, const std::vector<float>& cpu) {
    size_t inter = 0, uni = 0;
    for (size_t i = 0; i < gpu.size(); ++i) {
      const bool g = std::isfinite(gpu[i]), c = std::isfinite(cpu[i]);
      inter += g && c;
      uni += g || c;
    }
    return uni ? double(inter) / double(uni) : 1.0;
  }

  test::TempDir dir_;
  std::string path_;
  PackReader pack_;
  Renderer r_;
};

TEST_F(SlicesGl, DepthWithinTheSliceBoundAndShrinkingWithTheCount) {
  for (double deg : {60.0, 80.0, 89.0}) {
    const Camera cam = view(deg);
    const std::vector<float> ref = test::cpuDepth(pack_, cam);
    RenderSettings ps;
    ps.iterations = 12;
    ps.cull.subpixelSplats = false;
    FrameResult pf;
    ASSERT_TRUE(r_.render(cam, ps, pf, kReadDepth).isOk());
    const double parallax12 = iou(pf.depth, ref);
    double lastP99 = INFINITY;
    for (int n : {2, 4, 8, 16, 32, 64}) {
      const FrameResult fr = render(cam, n);
      const double bound = std::sqrt(3.0) * alongView(cam, n) + 0.5 * texel();
      const test::Agreement a = test::agreement(fr.depth, ref, bound);
      const size_t both = a.covered - a.coverageDiffers;
      std::printf("[slices-gl] %4.0f deg N %2d: %zu pixels both cover, %.2f%% within sqrt(3) spacings along the view + 0.5 texel "
                  "(%.4f), depth error p99 %.5f, IoU %.4f\n",
                  deg, n, both, both ? 100.0 * double(a.agree) / double(both) : 0.0, bound, a.p99Err, iou(fr.depth, ref));
      EXPECT_GT(both, 100u);
      EXPECT_GE(double(a.agree), 0.99 * double(both)) << deg << " deg, " << n << " slices";
      EXPECT_LE(a.p99Err, lastP99 * 1.05 + 1e-6) << deg << " deg, " << n << " slices";
      lastP99 = a.p99Err;
      if (n == 32) {
        std::printf("[slices-gl] %4.0f deg: parallax-12 IoU %.4f\n", deg, parallax12);
        EXPECT_GE(iou(fr.depth, ref), parallax12 - 0.005) << deg << " deg";
      }
    }
  }
}

TEST_F(SlicesGl, FragmentsGrowWithTheSliceCount) {
  const Camera cam = view(60);
  const FrameResult f8 = render(cam, 8), f16 = render(cam, 16);
  ASSERT_GT(f8.stats.fragments, 0u);
  const double ratio = double(f16.stats.fragments) / double(f8.stats.fragments);
  std::printf("[slices-gl] fragments %s: N 8 %llu, N 16 %llu (x%.2f)\n",
              f8.stats.fragmentsAreInvocations ? "shader invocations" : "samples passed",
              (unsigned long long)f8.stats.fragments, (unsigned long long)f16.stats.fragments, ratio);
  EXPECT_GE(ratio, 1.8);
  EXPECT_LE(ratio, 2.2);
}

TEST_F(SlicesGl, AxisSwitchingKeepsAGrazingViewClose) {
  const Camera cam = view(85);
  const std::vector<float> ref = test::cpuDepth(pack_, cam);
  const FrameResult switching = render(cam, 32), wOnly = render(cam, 32, 2);
  const test::Agreement s = test::agreement(switching.depth, ref, 0), w = test::agreement(wOnly.depth, ref, 0);
  std::printf("[slices-gl] 85 deg, 32 slices: IoU %.4f, depth error p99 %.4f with the axis switched per view; IoU %.4f, "
              "p99 %.4f slicing along w only\n", iou(switching.depth, ref), s.p99Err, iou(wOnly.depth, ref), w.p99Err);
  EXPECT_GE(iou(switching.depth, ref), 0.97);
  EXPECT_GT(w.p99Err, 1.3 * s.p99Err);  // measured 0.112 against 0.071
}

// --slices auto: near, the slices lie within a pixel (or a texel) of each other along the view,
// so depth and coverage hold; far, a cell gets few of them and the frame far fewer fragments.
TEST_F(SlicesGl, AutoCountFollowsTheDistance) {
  Camera near = view(60), far = near;
  far.eye = far.target + 8.0 * (near.eye - near.target);
  const std::vector<float> ref = test::cpuDepth(pack_, near);
  RenderSettings ps;
  ps.iterations = 12;
  ps.cull.subpixelSplats = false;
  FrameResult pf;
  ASSERT_TRUE(r_.render(near, ps, pf, kReadDepth).isOk());
  const FrameResult autoNear = render(near, 0);
  const double pixel = (near.eye - near.target).norm() * near.fovDeg * M_PI / 180 / near.height;
  const double bound = std::sqrt(3.0) * std::max(pixel, texel()) + 0.5 * texel();
  const test::Agreement a = test::agreement(autoNear.depth, ref, bound);
  const FrameResult autoFar = render(far, 0), fixedFar = render(far, 64);
  std::printf("[slices-gl] auto, near: IoU %.4f (parallax-12 %.4f), depth p99 %.5f (bound %.5f: a pixel %.5f, a texel %.5f); "
              "far (8x): %llu fragments against %llu with 64 slices\n",
              iou(autoNear.depth, ref), iou(pf.depth, ref), a.p99Err, bound, pixel, texel(),
              (unsigned long long)autoFar.stats.fragments, (unsigned long long)fixedFar.stats.fragments);
  EXPECT_GE(iou(autoNear.depth, ref), iou(pf.depth, ref) - 0.005);
  EXPECT_LE(a.p99Err, bound);
  EXPECT_LT(4 * autoFar.stats.fragments, fixedFar.stats.fragments);
}

}  // namespace
}  // namespace sa
