// End-to-end packing on synthetic and real inputs: chunking under a tiny memory budget gives
// the same cells as in-memory, NaN coordinates are skipped and counted, outputs are atomic.
#include "preprocess/pipeline.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "../common/test_util.h"
#include "atlas/pack_file.h"

namespace sa {
namespace {

TEST(Pipeline, SpherePackHasHeightFieldCells) {
  test::TempDir d;
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(40000, 1.0, Eigen::Vector3d(3, 4, 5), pts, nrm);
  test::writePointsPly(d.file("s.ply"), pts, &nrm);
  auto in = InputSet::open({d.file("s.ply")});
  ASSERT_TRUE(in.isOk());
  PackSummary sum;
  PackOptions opt;
  ASSERT_TRUE(packInput(*in, d.file("s.hfa"), opt, nullptr, sum).isOk());
  EXPECT_EQ(sum.pointsRead, 40000u);
  EXPECT_GE(sum.cells, 8u);
  EXPECT_EQ(sum.forcedCells, 0u);
  EXPECT_FALSE(sum.normalsEstimated);
  PackReader r;
  ASSERT_TRUE(r.open(d.file("s.hfa")).isOk());
  EXPECT_TRUE(r.verifyPages().isOk());
  EXPECT_NEAR(r.meta().origin[0], 3, 1e-3);
  // Every cell's points lie on the sphere: the heights of covered texels, mapped back to
  // world space, are within a texel of radius 1.
  size_t checked = 0;
  for (const CellRecord& c : r.cells()) {
    const Eigen::Vector3d O(c.origin), U(c.u), V(c.v), W(c.w);
    for (int j = 0; j < c.tileH; j += 3)
      for (int i = 0; i < c.tileW; i += 3) {
        const uint16_t k = r.texel(c, i, j);
        if (!k) continue;
        const double u = c.box[0] + (i + 0.5) * (c.box[1] - c.box[0]) / c.tileW;
        const double v = c.box[2] + (j + 0.5) * (c.box[3] - c.box[2]) / c.tileH;
        const Eigen::Vector3d p = O + U * u + V * v + W * decodeHeight(k, c.box[4], c.box[5]);
        const Eigen::Vector3d center = Eigen::Vector3d(3, 4, 5) - Eigen::Vector3d(r.meta().origin);
        EXPECT_NEAR((p - center).norm(), 1.0, 3 * r.meta().texelSize);
        ++checked;
      }
  }
  EXPECT_GT(checked, 1000u);
}

TEST(Pipeline, TinyMemoryBudgetGivesSameResultThroughManyChunks) {
  test::TempDir d;
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(200000, 1.0, Eigen::Vector3d::Zero(), pts, nrm);
  test::writePointsPly(d.file("s.ply"), pts, &nrm);
  auto in = InputSet::open({d.file("s.ply")});
  ASSERT_TRUE(in.isOk());
  PackOptions big, small;
  small.memBudget = 16u << 20;  // 16 MiB: about 70K points per chunk
  big.texelSize = small.texelSize = 0.01;
  PackSummary a, b;
  ASSERT_TRUE(packInput(*in, d.file("a.hfa"), big, nullptr, a).isOk());
  ASSERT_TRUE(packInput(*in, d.file("b.hfa"), small, nullptr, b).isOk());
  EXPECT_EQ(a.chunks, 1u);
  EXPECT_GT(b.chunks, 2u);
  EXPECT_EQ(a.pointsRead, b.pointsRead);
  // Chunks are octree nodes, so the cells are the same whether or not the data was chunked
  // (the cell list order may differ).
  EXPECT_EQ(a.cells, b.cells);
  EXPECT_EQ(a.texels, b.texels);
}

TEST(Pipeline, NonFiniteCoordinatesSkippedAndCounted) {
  test::TempDir d;
  test::writeText(d.file("n.ply"),
                  "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\nproperty float z\n"
                  "end_header\n0 0 0\n1 0 0\nnan 0 0\n0 1 0\n1 1 inf\n1 1 0\n");
  auto in = InputSet::open({d.file("n.ply")});
  ASSERT_TRUE(in.isOk());
  PackSummary sum;
  Status s = packInput(*in, d.file("n.hfa"), PackOptions{}, nullptr, sum);
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_EQ(sum.pointsRead, 4u);
  EXPECT_EQ(sum.pointsSkipped, 2u);
  PackReader r;
  ASSERT_TRUE(r.open(d.file("n.hfa")).isOk());
  for (const CellRecord& c : r.cells())
    for (double v : c.box) EXPECT_TRUE(std::isfinite(v));
}

TEST(Pipeline, FailedPackLeavesNoFile) {
  test::TempDir d;
  test::writeText(d.file("bad.ply"),
                  "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  "end_header\n0 0 0\n1 0 0\n0 1" + std::string(20, ' '));  // truncated in vertex 3
  auto in = InputSet::open({d.file("bad.ply")});
  ASSERT_TRUE(in.isOk());
  PackSummary sum;
  Status s = packInput(*in, d.file("out.hfa"), PackOptions{}, nullptr, sum);
  EXPECT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("bad.ply"), std::string::npos) << s.message();
  for (const auto& e : std::filesystem::directory_iterator(d.path()))
    EXPECT_EQ(e.path().filename().string(), "bad.ply") << "left behind: " << e.path();
}

TEST(PipelineReal, DragonMeshTakesTheTrianglePath) {
  auto in = InputSet::open({test::sharedData("stanford_bunny/reconstruction/bun_zipper_res2.ply")});
  ASSERT_TRUE(in.isOk());
  test::TempDir d;
  PackSummary tri, pts;
  ASSERT_TRUE(packInput(*in, d.file("t.hfa"), PackOptions{}, nullptr, tri).isOk());
  EXPECT_TRUE(tri.fromTriangles);
  EXPECT_EQ(tri.triangles, 16301u);
  PackOptions asPoints;
  asPoints.asPoints = true;
  ASSERT_TRUE(packInput(*in, d.file("p.hfa"), asPoints, nullptr, pts).isOk());
  EXPECT_FALSE(pts.fromTriangles);
  EXPECT_TRUE(pts.normalsEstimated);
}

}  // namespace
}  // namespace sa
