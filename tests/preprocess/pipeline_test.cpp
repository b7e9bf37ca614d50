// End-to-end packing on synthetic and real inputs: chunking under a tiny memory budget gives
// the same cells as in-memory, NaN coordinates are skipped and counted, outputs are atomic.
#include "preprocess/pipeline.h"

#include <gtest/gtest.h>

#include <random>
#include <Eigen/Geometry>

#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <sstream>

#include "../common/test_util.h"
#include "atlas/pack_file.h"
#include "formats/ply.h"
#include "preprocess/normals.h"

#include <Eigen/Geometry>
#include <flann/flann.hpp>

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
  auto warnedAboutBudget = [](const PackSummary& s) {
    for (const std::string& w : s.warnings)
      if (w.find("detail is lost") != std::string::npos) return true;
    return false;
  };
  EXPECT_FALSE(warnedAboutBudget(sum));
  // A texel budget that cannot hold the data's resolution coarsens the texels and says so.
  opt.texelBudget = 4096;
  PackSummary capped;
  ASSERT_TRUE(packInput(*in, d.file("capped.hfa"), opt, nullptr, capped).isOk());
  EXPECT_GT(capped.texelSize, 1.5 * sum.texelSize);
  EXPECT_TRUE(warnedAboutBudget(capped));
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
  // The budget also bounds a cell's points (maxLeafPoints): the same bound for both.
  big.octree.maxLeafPoints = small.octree.maxLeafPoints = maxLeafPoints(small.memBudget);
  PackSummary a, b;
  // The chunks' halos (preprocess/chunk_halo.h) are written in a phase of their own, with
  // progress; a pack of one chunk has none.
  std::map<int, std::vector<std::pair<uint64_t, uint64_t>>> halos;
  int pack = 0;
  const ProgressFn progress = [&](const char* phase, uint64_t done, uint64_t total) {
    if (std::string(phase) == "halos") halos[pack].emplace_back(done, total);
  };
  ASSERT_TRUE(packInput(*in, d.file("a.hfa"), big, progress, a).isOk());
  pack = 1;
  ASSERT_TRUE(packInput(*in, d.file("b.hfa"), small, progress, b).isOk());
  EXPECT_EQ(a.chunks, 1u);
  EXPECT_GT(b.chunks, 2u);
  EXPECT_TRUE(halos[0].empty());
  ASSERT_GE(halos[1].size(), 3u);
  EXPECT_EQ(halos[1].front().first, 0u);
  EXPECT_EQ(halos[1].back().first, halos[1].back().second);
  for (size_t i = 1; i < halos[1].size(); ++i) EXPECT_GE(halos[1][i].first, halos[1][i - 1].first);
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

namespace sa {
namespace {

struct MeshCollect : BatchSink {
  std::vector<double> xyz;
  std::vector<uint32_t> tris;
  std::vector<uint16_t> scan;
  Status onPoints(const PointBatch& b) override {
    for (size_t i = 0; i < b.size(); ++i) {
      xyz.insert(xyz.end(), {b.x[i], b.y[i], b.z[i]});
      scan.push_back(b.scan.empty() ? 0 : b.scan[i]);
    }
    return Status::ok();
  }
  Status onTriangles(const uint32_t* idx, size_t n) override {
    tris.insert(tris.end(), idx, idx + 3 * n);
    return Status::ok();
  }
};

// Estimated normals of the raw bunny scans, oriented toward each scan's scanner, must agree
// in sign with the normals of Stanford's reconstruction at the nearest vertex.
TEST(NormalsReal, BunnyScanNormalsFaceOutward) {
  auto input = InputSet::open({test::sharedData("stanford_bunny/scans/bun.conf")});
  ASSERT_TRUE(input.isOk());
  MeshCollect scans;
  ASSERT_TRUE(input->stream(scans, false).isOk());
  // Every 7th point keeps the test quick; normals are estimated over all of them.
  const size_t n = scans.xyz.size() / 3;
  std::vector<float> nrm(3 * n);
  NormalOrientation orient;
  orient.towardScanner = input->towardScanner();
  orient.scan = scans.scan.data();
  orient.scanStride = sizeof(uint16_t);
  estimateNormals(scans.xyz.data(), n, 24, orient, nrm.data());

  MeshCollect ref;
  ASSERT_TRUE(readPly(test::sharedData("stanford_bunny/reconstruction/bun_zipper.ply"), {}, ref).isOk());
  std::vector<double> refN(ref.xyz.size(), 0.0);
  for (size_t t = 0; t < ref.tris.size(); t += 3) {
    const Eigen::Vector3d a(&ref.xyz[3 * ref.tris[t]]), b(&ref.xyz[3 * ref.tris[t + 1]]), c(&ref.xyz[3 * ref.tris[t + 2]]);
    const Eigen::Vector3d fn = (b - a).cross(c - a);
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 3; ++j) refN[3 * ref.tris[t + k] + j] += fn[j];
  }
  flann::Matrix<double> data(ref.xyz.data(), ref.xyz.size() / 3, 3);
  flann::Index<flann::L2_Simple<double>> index(data, flann::KDTreeSingleIndexParams(10));
  index.buildIndex();
  size_t agree = 0, total = 0;
  for (size_t i = 0; i < n; i += 7) {
    const Eigen::Vector3d e(nrm[3 * i], nrm[3 * i + 1], nrm[3 * i + 2]);
    if (e.norm() < 0.5) continue;
    int idx;
    double dist;
    flann::Matrix<int> mi(&idx, 1, 1);
    flann::Matrix<double> md(&dist, 1, 1);
    flann::Matrix<double> mq(&scans.xyz[3 * i], 1, 3);
    index.knnSearch(mq, mi, md, 1, flann::SearchParams(64));
    if (std::sqrt(dist) > 1e-3) continue;  // scanner junk far from the reconstruction
    const Eigen::Vector3d r(&refN[3 * size_t(idx)]);
    ++total;
    agree += e.dot(r) > 0;
  }
  std::printf("bunny: %zu of %zu estimated normals face the same side as bun_zipper's (%.2f%%)\n", agree, total,
              100.0 * agree / total);
  EXPECT_GT(total, 40000u);
  EXPECT_GE(double(agree), 0.97 * double(total));
}

}  // namespace
}  // namespace sa

namespace sa {
namespace {

TEST(Pipeline, RepackingTheSameInputWithTheSameOptionsIsSkipped) {
  test::TempDir d;
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(20000, 1.0, Eigen::Vector3d::Zero(), pts, nrm);
  test::writePointsPly(d.file("s.ply"), pts, &nrm);
  auto in = InputSet::open({d.file("s.ply")});
  ASSERT_TRUE(in.isOk());
  PackSummary first, second, third, fourth;
  ASSERT_TRUE(packInput(*in, d.file("s.hfa"), PackOptions{}, nullptr, first).isOk());
  EXPECT_FALSE(first.upToDate);
  const auto mtime = std::filesystem::last_write_time(d.file("s.hfa"));
  ASSERT_TRUE(packInput(*in, d.file("s.hfa"), PackOptions{}, nullptr, second).isOk());
  EXPECT_TRUE(second.upToDate);
  EXPECT_EQ(second.cells, first.cells);
  EXPECT_EQ(second.texels, first.texels);
  EXPECT_EQ(std::filesystem::last_write_time(d.file("s.hfa")), mtime);
  PackOptions other;
  other.octree.maxDepth = 4;  // different options: a real repack
  ASSERT_TRUE(packInput(*in, d.file("s.hfa"), other, nullptr, third).isOk());
  EXPECT_FALSE(third.upToDate);
  // Same size, one byte changed in the input: a real repack.
  pts[10].x() += 1e-3;
  test::writePointsPly(d.file("s.ply"), pts, &nrm);
  auto in2 = InputSet::open({d.file("s.ply")});
  ASSERT_TRUE(in2.isOk());
  ASSERT_TRUE(packInput(*in2, d.file("s.hfa"), other, nullptr, fourth).isOk());
  EXPECT_FALSE(fourth.upToDate);
  EXPECT_NE(fourth.inputHash, third.inputHash);
}

}  // namespace
}  // namespace sa

#include "atlas/verify.h"

namespace sa {
namespace {

// Airborne lidar in US survey feet at (6.4e5, 8.5e5): packs seen from above (up +z by the LAS
// convention), with its colours, into a pack that verifies. Its estimated normals all face up,
// so the normal test alone kept the whole tile one height field (a canopy interpolated down to
// the ground); the layer test splits it: cells at clearly different heights over the same spot.
// The precision options (PackOptions::heightStep, normalTolerance, colourTolerance) on a real
// survey with colour and estimated normals: the same cells and coverage as a lossless pack,
// every height within its step, every normal within the tolerance (plus the 10-bit
// quantization's 0.06 degree), every colour within its levels; and fewer bytes.
TEST(PipelineReal, PrecisionOptionsBoundEveryTexelAndShrinkThePack) {
  auto in = InputSet::open({test::sharedData("lidar/autzen_trim.las")});
  ASSERT_TRUE(in.isOk()) << in.status().message();
  test::TempDir d;
  PackOptions lossless;
  lossless.heightStep = lossless.normalTolerance = 0;
  lossless.colourTolerance = 0;
  const PackOptions byDefault;
  PackSummary a, b;
  ASSERT_TRUE(packInput(*in, d.file("l.hfa"), lossless, nullptr, a).isOk());
  ASSERT_TRUE(packInput(*in, d.file("d.hfa"), byDefault, nullptr, b).isOk());
  std::printf("autzen: lossless %llu bytes, default %llu (%.2fx)\n", (unsigned long long)a.fileBytes,
              (unsigned long long)b.fileBytes, double(a.fileBytes) / double(b.fileBytes));
  EXPECT_GT(double(a.fileBytes), 1.3 * double(b.fileBytes));
  PackReader L, D;
  ASSERT_TRUE(L.open(d.file("l.hfa")).isOk());
  ASSERT_TRUE(D.open(d.file("d.hfa")).isOk());
  ASSERT_EQ(L.cells().size(), D.cells().size());
  ASSERT_TRUE(L.hasColor() && D.normalPage(0));
  const double cosTol = std::cos((kPointNormalTolerance + 0.07) * M_PI / 180);
  size_t texels = 0, moved[3] = {0, 0, 0};
  double worstHeight = 0;  // in texels
  for (size_t ci = 0; ci < L.cells().size(); ++ci) {
    const CellRecord &cl = L.cells()[ci], &cd = D.cells()[ci];
    ASSERT_EQ(cl.tileW, cd.tileW);
    ASSERT_EQ(cl.tileH, cd.tileH);
    const double texel = std::min((cl.box[1] - cl.box[0]) / cl.tileW, (cl.box[3] - cl.box[2]) / cl.tileH);
    for (int j = 0; j < cl.tileH; ++j)
      for (int i = 0; i < cl.tileW; ++i) {
        const uint16_t hl = L.texel(cl, i, j), hd = D.texel(cd, i, j);
        ASSERT_EQ(hl == 0, hd == 0) << "coverage changed in cell " << ci;
        if (!hl) continue;
        ++texels;
        const double dh = std::abs(decodeHeight(hl, cl.box[4], cl.box[5]) - decodeHeight(hd, cd.box[4], cd.box[5])) / texel;
        worstHeight = std::max(worstHeight, dh);
        ASSERT_LE(dh, kPointHeightStep + 1e-9) << "cell " << ci;
        double nl[3], nd[3];
        decodeNormal(L.normalTexel(cl, i, j), nl);
        decodeNormal(D.normalTexel(cd, i, j), nd);
        ASSERT_GE(nl[0] * nd[0] + nl[1] * nd[1] + nl[2] * nd[2], cosTol) << "cell " << ci;
        const uint8_t* kl = L.colorPage(cl.page) + 4 * ((size_t(cl.tileY) + j) * L.meta().pageWidth + cl.tileX + i);
        const uint8_t* kd = D.colorPage(cd.page) + 4 * ((size_t(cd.tileY) + j) * D.meta().pageWidth + cd.tileX + i);
        for (int c = 0; c < 3; ++c) ASSERT_LE(std::abs(int(kl[c]) - int(kd[c])), byDefault.colourTolerance);
        moved[0] += hl != hd;
        moved[1] += std::memcmp(L.normalTexel(cl, i, j), D.normalTexel(cd, i, j), kNormalBytes) != 0;
        moved[2] += std::memcmp(kl, kd, 3) != 0;
      }
  }
  std::printf("%zu texels: heights moved %zu (worst %.4f texel), normals %zu, colours %zu\n", texels, moved[0],
              worstHeight, moved[1], moved[2]);
  EXPECT_GT(moved[1], texels / 10) << "the normals' tolerance does something";
}

TEST(PipelineReal, AutzenLasPacksAsTerrainWithColourAndLayers) {
  auto in = InputSet::open({test::sharedData("lidar/autzen_trim.las")});
  ASSERT_TRUE(in.isOk()) << in.status().message();
  test::TempDir d;
  PackSummary sum;
  ASSERT_TRUE(packInput(*in, d.file("a.hfa"), PackOptions{}, nullptr, sum).isOk());
  EXPECT_EQ(sum.pointsRead, 110000u);
  EXPECT_TRUE(sum.hasColor);
  PackReader r;
  ASSERT_TRUE(r.open(d.file("a.hfa")).isOk());
  const VerifyReport v = verifyPack(r);
  EXPECT_TRUE(v.problems.empty()) << v.problems.front();
  EXPECT_EQ(r.meta().upSource, uint32_t(kUpConvention));
  EXPECT_NEAR(r.up().z(), 1.0, 1e-12);
  EXPECT_NEAR(r.meta().origin[0] + r.meta().boundsMin[0], 636001.76, 1e-6);
  EXPECT_GT(sum.cells, 100u);
  // Over-under pairs: cells whose footprints overlap in x, y and whose z ranges are more than
  // 10 ft apart (tree crowns over ground, the footbridge over the river).
  struct Box { Eigen::Vector3d lo, hi; };
  std::vector<Box> boxes;
  for (const CellRecord& c : r.cells()) {
    Box b{Eigen::Vector3d::Constant(1e300), Eigen::Vector3d::Constant(-1e300)};
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3d p = Eigen::Vector3d(c.origin) + Eigen::Vector3d(c.u) * c.box[k & 1] +
                                Eigen::Vector3d(c.v) * c.box[2 + ((k >> 1) & 1)] + Eigen::Vector3d(c.w) * c.box[4 + (k >> 2)];
      b.lo = b.lo.cwiseMin(p);
      b.hi = b.hi.cwiseMax(p);
    }
    boxes.push_back(b);
  }
  size_t pairs = 0;
  for (size_t i = 0; i < boxes.size() && pairs < 10; ++i)
    for (size_t j = 0; j < boxes.size(); ++j) {
      const Box &a = boxes[i], &b = boxes[j];
      const bool overlapXY = a.lo.x() < b.hi.x() && b.lo.x() < a.hi.x() && a.lo.y() < b.hi.y() && b.lo.y() < a.hi.y();
      if (overlapXY && a.lo.z() > b.hi.z() + 10) ++pairs;
    }
  EXPECT_GE(pairs, 10u) << "no cells over cells: layered structure was not split";
}

}  // namespace
}  // namespace sa

namespace sa {
namespace {

// Packs `text` written as a .xyz file (or a PLY when ext says so); returns the reader's meta.
PackMeta packText(const test::TempDir& d, const std::string& name, const std::string& text, PackSummary* sum = nullptr,
                  const PackOptions& opt = {}) {
  test::writeText(d.file(name), text);
  auto in = InputSet::open({d.file(name)});
  EXPECT_TRUE(in.isOk()) << (in.isOk() ? "" : in.status().message());
  PackSummary s;
  EXPECT_TRUE(packInput(*in, d.file(name + ".hfa"), opt, nullptr, s).isOk());
  if (sum) *sum = s;
  PackReader r;
  EXPECT_TRUE(r.open(d.file(name + ".hfa")).isOk());
  return r.meta();
}

// A terrain-like cloud (wide in x and y, thin in z) as a plain .xyz file: no format convention
// to lean on, so up comes from the data - the thin axis, on the side the surface faces.
std::string terrainXyz(double lengthX, double lengthY, int n, double zScale) {
  std::string s;
  uint32_t seed = 17;
  auto rnd = [&] { return (seed = seed * 1664525u + 1013904223u) / 4294967296.0; };
  for (int i = 0; i < n; ++i) {
    const double x = rnd() * lengthX, y = rnd() * lengthY;
    const double z = zScale * std::sin(2 * M_PI * x / 50) * std::sin(2 * M_PI * y / 50);  // no skew
    s += std::to_string(x) + " " + std::to_string(y) + " " + std::to_string(z) + "\n";
  }
  return s;
}

TEST(UpAxis, FromGivenConventionAndData) {
  test::TempDir d;
  // Terrain in an .xyz file: the z axis from the data (the heights do not skew: as it points).
  PackMeta m = packText(d, "terrain.xyz", terrainXyz(200, 150, 20000, 2.0));
  EXPECT_EQ(m.upSource, uint32_t(kUpFromData));
  EXPECT_NEAR(m.up[2], 1.0, 1e-9);
  // Things stand up from the ground: with posts sticking up, heights skew to +z; the same
  // terrain upside down (z negated) skews to -z, so up is -z.
  std::string posts = terrainXyz(200, 150, 20000, 2.0), flipped;
  for (int i = 0; i < 2000; ++i)
    posts += std::to_string(20 + 40 * (i % 5)) + " " + std::to_string(20 + 25 * (i / 400)) + " " + std::to_string(0.025 * (i % 400)) + "\n";
  {
    std::istringstream in(posts);
    double x, y, z;
    while (in >> x >> y >> z) flipped += std::to_string(x) + " " + std::to_string(y) + " " + std::to_string(-z) + "\n";
  }
  m = packText(d, "posts.xyz", posts);
  EXPECT_NEAR(m.up[2], 1.0, 1e-9);
  m = packText(d, "flipped.xyz", flipped);
  EXPECT_NEAR(m.up[2], -1.0, 1e-9);
  // Given: stored as given.
  PackOptions given;
  given.up = Eigen::Vector3d(0, 0, -1);
  m = packText(d, "given.xyz", terrainXyz(200, 150, 2000, 2.0), nullptr, given);
  EXPECT_EQ(m.upSource, uint32_t(kUpGiven));
  EXPECT_NEAR(m.up[2], -1.0, 1e-12);
  // A compact object in a PLY: the format's usual +y.
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(4000, 1.0, Eigen::Vector3d::Zero(), pts, nrm);
  test::writePointsPly(d.file("ball.ply"), pts, &nrm);
  auto in = InputSet::open({d.file("ball.ply")});
  ASSERT_TRUE(in.isOk());
  PackSummary sum;
  ASSERT_TRUE(packInput(*in, d.file("ball.hfa"), PackOptions{}, nullptr, sum).isOk());
  EXPECT_EQ(sum.upSource, uint32_t(kUpConvention));
  EXPECT_NEAR(sum.up.y(), 1.0, 1e-12);
}

// A Kinect-style organized PCD is a camera's image, y down: up starts from -y and becomes the
// normal of the largest flat area near it (the table top / floor of PCL's mug scene).
TEST(UpAxisReal, OrganizedPcdStandsOnItsTable) {
  auto in = InputSet::open({test::sharedData("pcd/table_scene_mug_stereo_textured.pcd")});
  ASSERT_TRUE(in.isOk()) << in.status().message();
  test::TempDir d;
  PackSummary sum;
  ASSERT_TRUE(packInput(*in, d.file("t.hfa"), PackOptions{}, nullptr, sum).isOk());
  EXPECT_EQ(sum.upSource, uint32_t(kUpFromData));
  EXPECT_GT(sum.up.dot(-Eigen::Vector3d::UnitY()), std::cos(45 * M_PI / 180)) << sum.up.transpose();
  EXPECT_LT(sum.up.dot(-Eigen::Vector3d::UnitY()), 0.999) << "not refined: " << sum.up.transpose();
}

// A sparse strip: 501 m x 5 m, 1000 points. It made a 2048^2 page (8 MB); pages now fit their
// tiles and a point input keeps at most 8 texels per point.
// An open sheet without normals or a scanner (a tilted, undulating wall scan): its estimated
// normals all take one side, so every cell faces the same way and a viewer sees the whole sheet
// from that side. Oriented away from the cloud's centroid, which lies in the sheet, the bumps
// above and below it faced opposite ways and half the sheet was drawn from each side only.
TEST(Pipeline, OpenSheetFacesOneWay) {
  test::TempDir d;
  std::vector<Eigen::Vector3d> pts;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  std::mt19937 rng(4);
  std::normal_distribution<double> noise(0, 0.1);
  std::uniform_real_distribution<double> jitter(0, 1);
  for (int j = 0; j < 200; ++j)
    for (int i = 0; i < 200; ++i) {
      const double x = i + jitter(rng), y = j + jitter(rng);
      const double h = 4 * std::sin(2 * M_PI * x / 150) * std::cos(2 * M_PI * y / 185) + noise(rng);
      pts.push_back(R * Eigen::Vector3d(x, y, h) + Eigen::Vector3d(100, 50, 20));
    }
  test::writePointsPly(d.file("wall.ply"), pts, nullptr);
  auto in = InputSet::open({d.file("wall.ply")});
  ASSERT_TRUE(in.isOk());
  PackSummary sum;
  ASSERT_TRUE(packInput(*in, d.file("wall.hfa"), PackOptions{}, nullptr, sum).isOk());
  EXPECT_TRUE(sum.normalsEstimated);
  PackReader r;
  ASSERT_TRUE(r.open(d.file("wall.hfa")).isOk());
  size_t facing = 0, away = 0;
  for (const CellRecord& c : r.cells()) (Eigen::Vector3d(c.w).dot(R.col(2)) > 0 ? facing : away) += 1;
  std::printf("open sheet: %u cells (%u forced), %zu facing +n, %zu facing -n\n", sum.cells, sum.forcedCells, facing, away);
  EXPECT_TRUE(facing == 0 || away == 0);
  EXPECT_LE(sum.cells, 16u);
  EXPECT_EQ(sum.forcedCells, 0u);
}

// A sphere whose cap x < -2.5 (a quarter of its area) holds as many points as the rest, as where
// a statue's face was scanned closer or a survey's flight lines overlap: the pack's spacing is
// between the two, the cap's cells take the texel of their own points' spacing, finer than the
// pack's, so they keep their detail; the rest keeps the pack's.
TEST(Pipeline, TexelsFollowTheLocalSpacing) {
  test::TempDir d;
  std::vector<Eigen::Vector3d> pts, nrm;
  std::mt19937 rng(5);
  std::normal_distribution<double> g;
  size_t dense = 0, sparse = 0;
  while (dense < 20000 || sparse < 20000) {
    Eigen::Vector3d n(g(rng), g(rng), g(rng));
    n.normalize();
    size_t& count = n.x() < -0.5 ? dense : sparse;
    if (count >= 20000) continue;
    ++count;
    pts.push_back(5 * n);
    nrm.push_back(n);
  }
  test::writePointsPly(d.file("t.ply"), pts, &nrm);
  auto in = InputSet::open({d.file("t.ply")});
  ASSERT_TRUE(in.isOk());
  PackOptions uncapped;
  uncapped.texelBudget = 64u << 20;
  PackSummary local;
  ASSERT_TRUE(packInput(*in, d.file("t.hfa"), uncapped, nullptr, local).isOk());
  PackReader r;
  ASSERT_TRUE(r.open(d.file("t.hfa")).isOk());
  std::vector<double> denseT, sparseT;
  for (const CellRecord& c : r.cells()) {
    const Eigen::Vector3d centre = Eigen::Vector3d(c.origin) + Eigen::Vector3d(r.meta().origin);
    const double t = (c.box[1] - c.box[0]) / c.tileW;
    EXPECT_NEAR(t, (c.box[3] - c.box[2]) / c.tileH, 1e-6 * t) << "texels are square";
    if (centre.x() < -2.5) denseT.push_back(t);  // the octants on the cap's side
    if (centre.x() > 0) sparseT.push_back(t);
  }
  ASSERT_GE(denseT.size(), 4u);
  ASSERT_GE(sparseT.size(), 4u);
  std::sort(denseT.begin(), denseT.end());
  std::sort(sparseT.begin(), sparseT.end());
  const double td = denseT[denseT.size() / 2], ts = sparseT[sparseT.size() / 2];
  std::printf("local texels: dense %.4f (%zu cells), sparse %.4f (%zu cells), ratio %.2f; pack area spacing %.4f; "
              "%llu texels for 40000 points, range %.4f-%.4f\n", td, denseT.size(), ts, sparseT.size(), ts / td,
              local.areaSpacing, (unsigned long long)local.texels, local.texelMin, local.texelMax);
  // Dense cells: half their own area spacing. Sparse ones: the pack's texel (half the points'
  // mean area spacing), never coarser.
  const double denseSpacing = std::sqrt(2 * M_PI * 5 * 2.5 / 20000);  // the side of the area per point
  EXPECT_NEAR(td, 0.5 * denseSpacing, 0.2 * 0.5 * denseSpacing);
  EXPECT_DOUBLE_EQ(ts, 0.5 * local.areaSpacing);
  EXPECT_DOUBLE_EQ(local.texelMax, 0.5 * local.areaSpacing);
  EXPECT_LT(td, 0.85 * ts);
  EXPECT_TRUE(std::none_of(local.warnings.begin(), local.warnings.end(),
                           [](const std::string& w) { return w.find("detail is lost") != std::string::npos; }));
  // The default: at most kMaxTexelsPerPoint per point, all cells coarsened alike if needed.
  PackSummary byDefault;
  ASSERT_TRUE(packInput(*in, d.file("default.hfa"), PackOptions{}, nullptr, byDefault).isOk());
  EXPECT_LE(byDefault.texels, kMaxTexelsPerPoint * 40000);
  EXPECT_NEAR(byDefault.texelMax / byDefault.texelMin, local.texelMax / local.texelMin, 0.01 * local.texelMax / local.texelMin);
  // --texel-size: one texel for every cell.
  PackOptions one;
  one.texelSize = 0.04;
  PackSummary fixed;
  ASSERT_TRUE(packInput(*in, d.file("f.hfa"), one, nullptr, fixed).isOk());
  EXPECT_DOUBLE_EQ(fixed.texelMin, 0.04);
  EXPECT_DOUBLE_EQ(fixed.texelMax, 0.04);
  // A cap coarsens every cell by the same factor, keeping the dense part finer, and says so.
  PackOptions capped;
  capped.texelBudget = local.texels / 4;
  PackSummary c;
  ASSERT_TRUE(packInput(*in, d.file("c.hfa"), capped, nullptr, c).isOk());
  EXPECT_LE(c.texels, capped.texelBudget);
  EXPECT_GT(c.texelSize, 1.5 * local.texelSize);
  EXPECT_NEAR(c.texelMax / c.texelMin, local.texelMax / local.texelMin, 0.01 * local.texelMax / local.texelMin);
  EXPECT_TRUE(std::any_of(c.warnings.begin(), c.warnings.end(),
                          [](const std::string& w) { return w.find("detail is lost; raise --texels") != std::string::npos; }));
}

// Random points over rolling terrain, cut into nearly flat cells: a cell's fit has no preferred
// direction in its plane, so its tile takes a cube axis projected onto it, and the tiles cover
// little more than the terrain. Before, the fit's in-plane axes turned tiles up to 45 degrees
// from the cells' footprints (measured: no cell along the cube's axes, tiles 1.81x the
// terrain's area; now 178 of 193 cells, 1.28x).
TEST(Pipeline, FlatTerrainTilesFollowTheCubeAxes) {
  test::TempDir d;
  PackSummary sum;
  PackOptions opt;
  opt.octree.maxAngleDeg = 20;  // many cells, each nearly flat
  packText(d, "flat.xyz", terrainXyz(200, 150, 40000, 3), &sum, opt);
  PackReader r;
  ASSERT_TRUE(r.open(d.file("flat.xyz.hfa")).isOk());
  size_t along = 0, cells = 0;
  double area = 0;
  for (const CellRecord& c : r.cells()) {
    if (c.flags & kCellDegenerate) continue;
    ++cells;
    const Eigen::Vector3d u(c.u), v(c.v), w(c.w);
    EXPECT_NEAR(u.dot(v), 0, 1e-9);
    EXPECT_NEAR(u.cross(v).dot(w), 1, 1e-9) << "right-handed";
    for (int a = 0; a < 3; ++a) {  // U is a cube axis projected onto the plane
      const Eigen::Vector3d p = Eigen::Vector3d::Unit(a) - w[a] * w;
      if (p.norm() > 0.5 && std::abs(u.dot(p.normalized())) > 1 - 1e-9) {
        ++along;
        break;
      }
    }
    const double t = (c.box[1] - c.box[0]) / c.tileW;
    area += double(c.tileW) * c.tileH * t * t;
  }
  std::printf("flat terrain: %zu of %zu cells along the cube's axes; tiles cover %.3fx the terrain's area\n", along,
              cells, area / (200 * 150));
  ASSERT_GT(cells, 20u);
  EXPECT_GE(along, cells * 8 / 10);
  EXPECT_LT(area, 1.45 * 200 * 150);
}

TEST(Pipeline, SparseStripStaysSmall) {
  test::TempDir d;
  PackSummary sum;
  const PackMeta m = packText(d, "strip.xyz", terrainXyz(501, 5, 1000, 0.3), &sum);
  std::printf("strip: %u page(s) of %ux%u, %llu texels, %llu bytes (%.1f per point)\n", m.pageCount, m.pageWidth,
              m.pageHeight, (unsigned long long)m.texelsUsed, (unsigned long long)sum.fileBytes, sum.fileBytes / 1000.0);
  EXPECT_LE(m.texelsUsed, 8u * 1000u);
  EXPECT_LE(uint64_t(m.pageWidth) * m.pageHeight * m.pageCount, 4u * m.texelsUsed);
  EXPECT_LT(sum.fileBytes, 200u * 1000u);
}

}  // namespace
}  // namespace sa

namespace sa {
namespace {

// The points are hashed as the bounds pass reads them; faces are not streamed there, so a mesh
// whose vertices stay and whose triangles change must still repack.
TEST(Pipeline, AMeshWhoseTrianglesChangeIsRepacked) {
  test::TempDir d;
  auto write = [&](bool flip) {
    std::string ply = "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
                      "element face 4\nproperty list uchar int vertex_indices\nend_header\n"
                      "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0.5 0.5 0.3\n";
    ply += flip ? "3 0 1 2\n3 0 2 3\n3 0 1 4\n3 1 2 4\n" : "3 0 1 4\n3 1 2 4\n3 2 3 4\n3 3 0 4\n";
    test::writeText(d.file("m.ply"), ply);
  };
  PackSummary a, b, c;
  write(false);
  auto in = InputSet::open({d.file("m.ply")});
  ASSERT_TRUE(in.isOk()) << in.status().message();
  ASSERT_TRUE(packInput(*in, d.file("m.hfa"), PackOptions{}, nullptr, a).isOk());
  ASSERT_TRUE(packInput(*in, d.file("m.hfa"), PackOptions{}, nullptr, b).isOk());
  EXPECT_TRUE(b.upToDate);
  write(true);  // same vertices, same size, other triangles
  auto in2 = InputSet::open({d.file("m.ply")});
  ASSERT_TRUE(in2.isOk());
  ASSERT_TRUE(packInput(*in2, d.file("m.hfa"), PackOptions{}, nullptr, c).isOk());
  EXPECT_FALSE(c.upToDate);
  EXPECT_NE(c.inputHash, a.inputHash);
}

}  // namespace
}  // namespace sa

namespace sa {
namespace {

// Long phases report progress from inside a chunk, not only when a chunk ends: a one-chunk pack
// of the bunny's scans (about 360k points) moves its octree (normals) and heightmaps bars in
// steps, each phase starting at 0 and ending at its total, never going back.
TEST(Pipeline, ProgressMovesInsideAChunk) {
  ASSERT_TRUE(test::haveSharedData()) << "../shared/data is missing";
  test::TempDir dir;
  auto input = InputSet::open({test::sharedData("stanford_bunny/scans/bun.conf")});
  ASSERT_TRUE(input.isOk());
  std::mutex mu;
  std::map<std::string, std::vector<std::pair<uint64_t, uint64_t>>> seen;
  const ProgressFn progress = [&](const char* phase, uint64_t done, uint64_t total) {
    std::lock_guard<std::mutex> lock(mu);
    seen[phase].emplace_back(done, total);
  };
  PackSummary sum;
  ASSERT_TRUE(packInput(*input, dir.file("p.hfa"), PackOptions{}, progress, sum).isOk());
  ASSERT_EQ(sum.chunks, 1u);
  for (const char* phase : {"octree", "heightmaps"}) {
    const auto& v = seen[phase];
    ASSERT_GE(v.size(), 3u) << phase;
    EXPECT_EQ(v.front().first, 0u) << phase;
    EXPECT_EQ(v.back().first, v.back().second) << phase;
    size_t inside = 0;
    for (size_t i = 0; i < v.size(); ++i) {
      if (i > 0) {
        EXPECT_GE(v[i].first, v[i - 1].first) << phase;
      }
      inside += v[i].first > 0 && v[i].first < v[i].second;
    }
    std::printf("[progress] %s: %zu reports, %zu between 0 and the end\n", phase, v.size(), inside);
    EXPECT_GE(inside, 5u) << phase;
  }
}

}  // namespace
}  // namespace sa
