// Accuracy on real data: the bunny packed from its 10 raw range scans (aligned by bun.conf),
// rendered on the GPU path from 4 orbit views at 512x512, against a depth render of Stanford's
// zippered reconstruction bun_zipper.ply (its triangles rasterized with the same cameras).
#include <gtest/gtest.h>

#include <cstdio>

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

struct ViewStats {
  double iouMin = 1, medMax = 0;
};

ViewStats compareViews(const PackReader& pack, const TriangleMesh& mesh, int views, int size, const char* name) {
  EglContext ctx;
  EXPECT_TRUE(ctx.init().isOk());
  Renderer r;
  EXPECT_TRUE(r.init(pack).isOk());
  // Cameras framed on the reference mesh's bounding box.
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (size_t i = 0; i < mesh.positions.size(); i += 3) {
    lo = lo.cwiseMin(Eigen::Vector3d(&mesh.positions[i]));
    hi = hi.cwiseMax(Eigen::Vector3d(&mesh.positions[i]));
  }
  const double diag = (hi - lo).norm();
  auto cams = orbitCameras(lo, hi, views, Eigen::Vector3d::UnitY(), 40, size, size);
  ViewStats st;
  for (size_t v = 0; v < cams.size(); ++v) {
    FrameResult fr;
    EXPECT_TRUE(r.render(cams[v], RenderSettings{}, fr, true).isOk());
    const auto ref = referenceDepth(mesh, cams[v]);
    const DepthComparison c = compareDepth(fr.depth, ref, diag);
    std::printf("%s view %zu: IoU %.4f, depth error median %.5f%% p95 %.4f%% of the diagonal "
                "(both %zu, only render %zu, only reference %zu)\n",
                name, v, c.iou, 100 * c.medianRelError, 100 * c.p95RelError, c.both, c.onlyTest, c.onlyRef);
    st.iouMin = std::min(st.iouMin, c.iou);
    st.medMax = std::max(st.medMax, c.medianRelError);
  }
  return st;
}

// The triangle path: the dragon mesh rasterized into height maps, against the same mesh.
TEST(Accuracy, DragonMeshTrianglePathAgainstItself) {
  ASSERT_TRUE(test::haveSharedData()) << "../shared/data is missing";
  test::TempDir dir;
  const std::string src = test::sharedData("stanford_dragon/reconstruction/dragon_vrip.ply");
  auto input = InputSet::open({src});
  ASSERT_TRUE(input.isOk()) << input.status().message();
  PackSummary sum;
  ASSERT_TRUE(packInput(*input, dir.file("d.hfa"), PackOptions{}, nullptr, sum).isOk());
  EXPECT_TRUE(sum.fromTriangles);
  PackReader pack;
  ASSERT_TRUE(pack.open(dir.file("d.hfa")).isOk());
  auto mesh = loadMesh(src);
  ASSERT_TRUE(mesh.isOk());
  const ViewStats st = compareViews(pack, *mesh, 4, 512, "dragon");
  std::printf("dragon: %u cells (%u forced), worst IoU %.4f, worst median depth error %.5f%%\n", sum.cells,
              sum.forcedCells, st.iouMin, 100 * st.medMax);
  EXPECT_GE(st.iouMin, 0.97);
  EXPECT_LE(st.medMax, 0.002);
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

// The reference-free measure (eval's "far"): every rendered surface pixel's distance to the
// nearest input point, in sample spacings, over 8 orbit views about the pack's up axis.
FarStats farOverOrbit(const PackReader& pack, int views, int size) {
  EglContext ctx;
  EXPECT_TRUE(ctx.init().isOk());
  Renderer r;
  EXPECT_TRUE(r.init(pack).isOk());
  SourcePoints src;
  EXPECT_TRUE(loadSourcePoints(pack, src).isOk());
  const NearestSamples samples(std::move(src.xyz));
  Eigen::Vector3d lo, hi;
  const Eigen::Vector3d origin(pack.meta().origin);
  lo = origin + Eigen::Vector3d(pack.meta().boundsMin);
  hi = origin + Eigen::Vector3d(pack.meta().boundsMax);
  std::vector<double> all;
  for (const Camera& cam : orbitCameras(lo, hi, views, pack.viewUp(), 40, size, size)) {
    FrameResult fr;
    EXPECT_TRUE(r.render(cam, RenderSettings{}, fr, kReadDepth).isOk());
    const std::vector<double> hits = surfacePoints(cam, fr.depth, origin);
    std::vector<double> d(hits.size() / 3);
    samples.distances(hits.data(), d.size(), d.data());
    for (double& x : d) x /= pack.meta().sampleSpacing;
    all.insert(all.end(), d.begin(), d.end());
  }
  return summarizeFar(all);
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
}

INSTANTIATE_TEST_SUITE_P(Scans, FarReal,
                         ::testing::Values("lidar/autzen_trim.las", "lidar/lone-star.las",
                                           "pcd/table_scene_mug_stereo_textured.pcd"));

}  // namespace
}  // namespace sa
