// Accuracy on real data: the bunny packed from its 10 raw range scans (aligned by bun.conf),
// rendered on the GPU path from 4 orbit views at 512x512, against a depth render of Stanford's
// zippered reconstruction bun_zipper.ply (its triangles rasterized with the same cameras).
#include <gtest/gtest.h>

#include <cstdio>

#include "../common/test_util.h"
#include "preprocess/pipeline.h"
#include "viewer/egl_context.h"
#include "viewer/reference.h"
#include "viewer/renderer.h"

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
  // Cameras framed on the reference mesh's bounding box.
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (size_t i = 0; i < mesh->positions.size(); i += 3) {
    lo = lo.cwiseMin(Eigen::Vector3d(&mesh->positions[i]));
    hi = hi.cwiseMax(Eigen::Vector3d(&mesh->positions[i]));
  }
  const double diag = (hi - lo).norm();
  auto cams = orbitCameras(lo, hi, 4, Eigen::Vector3d::UnitY(), 40, 512, 512);
  double iouMin = 1, medMax = 0;
  for (size_t v = 0; v < cams.size(); ++v) {
    FrameResult fr;
    ASSERT_TRUE(r.render(cams[v], RenderSettings{}, fr, true).isOk());
    const auto ref = referenceDepth(*mesh, cams[v]);
    const DepthComparison c = compareDepth(fr.depth, ref, diag);
    std::printf("bunny view %zu: IoU %.4f, depth error median %.5f%% p95 %.4f%% of the diagonal "
                "(both %zu, only render %zu, only reference %zu)\n",
                v, c.iou, 100 * c.medianRelError, 100 * c.p95RelError, c.both, c.onlyTest, c.onlyRef);
    iouMin = std::min(iouMin, c.iou);
    medMax = std::max(medMax, c.medianRelError);
  }
  std::printf("bunny: %u cells, worst IoU %.4f, worst median depth error %.5f%%\n", sum.cells, iouMin, 100 * medMax);
  EXPECT_GE(iouMin, 0.97);
  EXPECT_LE(medMax, 0.002);
}

}  // namespace
}  // namespace sa
