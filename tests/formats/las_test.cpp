#include "formats/las.h"
#include "formats/source.h"
#include "preprocess/pipeline.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <map>
#include <cstring>
#include <fstream>

#include <Eigen/Geometry>

#include "../common/test_util.h"

namespace sa {
namespace {

struct Collect : BatchSink {
  uint64_t n = 0;
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  int maxColor = -1;
  Status onPoints(const PointBatch& b) override {
    for (size_t i = 0; i < b.size(); ++i) {
      const double p[3] = {b.x[i], b.y[i], b.z[i]};
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], p[a]);
        hi[a] = std::max(hi[a], p[a]);
      }
      if (b.hasColors()) maxColor = std::max({maxColor, int(b.r[i]), int(b.g[i]), int(b.b[i])});
    }
    n += b.size();
    return Status::ok();
  }
};

std::vector<char> slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::vector<char>((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

// PROVENANCE.md: LAS 1.2 format 3, 110000 points, x 636001.76-637179.22, y 848935.20-849497.90,
// z 406.26-520.51; RGB at most 236 (8-bit values in 16-bit fields).
TEST(LasReal, AutzenCountsBoundsAndEightBitColour) {
  Collect c;
  LasHeader h;
  Status s = readLas(test::sharedData("lidar/autzen_trim.las"), 1 << 14, c, &h);
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_EQ(h.pointFormat, 3);
  EXPECT_EQ(c.n, 110000u);
  EXPECT_NEAR(c.lo[0], 636001.76, 1e-6);
  EXPECT_NEAR(c.hi[0], 637179.22, 1e-6);
  EXPECT_NEAR(c.lo[1], 848935.20, 1e-6);
  EXPECT_NEAR(c.hi[1], 849497.90, 1e-6);
  EXPECT_NEAR(c.lo[2], 406.26, 1e-6);
  EXPECT_NEAR(c.hi[2], 520.51, 1e-6);
  EXPECT_TRUE(h.color8bit);
  EXPECT_EQ(c.maxColor, 236);  // kept as stored, not divided by 256
}

// Terrestrial RIEGL scan, LAS 1.1 format 1 (no colour), 0.25 mm scale, 518862 points.
TEST(LasReal, LoneStarTerrestrialScan) {
  Collect c;
  LasHeader h;
  Status s = readLas(test::sharedData("lidar/lone-star.las"), 1 << 15, c, &h);
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_EQ(h.pointFormat, 1);
  EXPECT_EQ(c.n, 518862u);
  EXPECT_FALSE(h.hasColor);
  EXPECT_GT(c.lo[0], 515368.0);
  EXPECT_LT(c.hi[0], 515401.1);
  EXPECT_GT(c.lo[2], 2322.8);
  EXPECT_LT(c.hi[2], 2338.7);
  for (int a = 0; a < 3; ++a) {  // header bounds are up to 2 mm looser than the points
    EXPECT_LE(h.min[a], c.lo[a] + 1e-9);
    EXPECT_GE(h.max[a], c.hi[a] - 1e-9);
  }
}

TEST(LasReal, LazIsRefusedWithAHint) {
  Collect c;
  Status s = readLas(test::sharedData("lidar/lone-star.laz"), 1024, c);
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.kind(), ErrorKind::kBadInput);
  EXPECT_NE(s.message().find("LAZ"), std::string::npos);
  EXPECT_NE(s.message().find("laszip"), std::string::npos);
}

// The "colour that is not colour": autzen with every RGB field set to zero is read and
// packed without colour (it rendered black on the dark background), and info says why.
TEST(LasReal, AllZeroRgbIsNoColour) {
  test::TempDir d;
  auto bytes = slurp(test::sharedData("lidar/autzen_trim.las"));
  ASSERT_GT(bytes.size(), 227u);
  uint32_t offset = 0, count = 0;
  uint16_t length = 0;
  std::memcpy(&offset, &bytes[96], 4);
  std::memcpy(&length, &bytes[105], 2);
  std::memcpy(&count, &bytes[107], 4);
  ASSERT_EQ(uint8_t(bytes[104]), 3);  // format 3: RGB at byte 28 of each record
  for (uint64_t i = 0; i < count; ++i) std::memset(&bytes[offset + i * length + 28], 0, 6);
  test::writeBytes(d.file("black.las"), bytes);
  Collect c;
  LasHeader h;
  ASSERT_TRUE(readLas(d.file("black.las"), 1 << 15, c, &h).isOk());
  EXPECT_FALSE(h.hasColor);
  EXPECT_TRUE(h.colorConstant);
  EXPECT_EQ(c.maxColor, -1);  // no colour channel delivered
  auto in = InputSet::open({d.file("black.las")});
  ASSERT_TRUE(in.isOk()) << in.status().message();
  EXPECT_NE(in->files()[0].detail.find("RGB fields all 0,0,0 (no colour)"), std::string::npos) << in->files()[0].detail;
  PackSummary sum;
  ASSERT_TRUE(packInput(*in, d.file("black.hfa"), PackOptions{}, nullptr, sum).isOk());
  EXPECT_FALSE(sum.hasColor);
}

// A PLY whose colour properties hold one colour for every vertex: no colour, with a warning.
TEST(Ply, ConstantColourIsNoColour) {
  test::TempDir d;
  std::string t = "ply\nformat ascii 1.0\nelement vertex 400\nproperty float x\nproperty float y\nproperty float z\n"
                  "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
  for (int i = 0; i < 400; ++i)
    t += std::to_string(i % 20) + " " + std::to_string(i / 20) + " " + std::to_string(0.1 * std::sin(i)) + " 200 30 30\n";
  test::writeText(d.file("red.ply"), t);
  auto in = InputSet::open({d.file("red.ply")});
  ASSERT_TRUE(in.isOk()) << in.status().message();
  PackSummary sum;
  ASSERT_TRUE(packInput(*in, d.file("red.hfa"), PackOptions{}, nullptr, sum).isOk());
  EXPECT_FALSE(sum.hasColor);
  bool warned = false;
  for (const std::string& w : sum.warnings) warned |= w.find("same colour") != std::string::npos;
  EXPECT_TRUE(warned);
}

TEST(Las, TruncatedAndHugeCountsAreRejectedBeforeReading) {
  test::TempDir d;
  auto bytes = slurp(test::sharedData("lidar/autzen_trim.las"));
  ASSERT_GT(bytes.size(), 10000u);
  auto cut = bytes;
  cut.resize(bytes.size() - 1000);
  test::writeBytes(d.file("cut.las"), cut);
  Collect c;
  Status s = readLas(d.file("cut.las"), 1024, c);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("at most"), std::string::npos) << s.message();
  EXPECT_EQ(c.n, 0u);
  auto huge = std::vector<char>(bytes.begin(), bytes.begin() + 4096);
  const uint32_t n = 4000000000u;
  std::memcpy(&huge[107], &n, 4);
  test::writeBytes(d.file("huge.las"), huge);
  s = readLas(d.file("huge.las"), 1024, c);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("4000000000"), std::string::npos) << s.message();
  test::writeText(d.file("not.las"), std::string(400, 'x'));
  s = readLas(d.file("not.las"), 1024, c);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("LASF"), std::string::npos);
}

}  // namespace
}  // namespace sa

#include "formats/source.h"
#include "formats/text.h"
#include "preprocess/pipeline.h"

namespace sa {
namespace {

TEST(Text, DelimitersHeadersPtsCountsAndErrors) {
  test::TempDir d;
  test::writeText(d.file("a.csv"), "X;Y;Z;Intensity\n1;2;3;7\n4;5;6;8\n");
  auto L = readTextLayout(d.file("a.csv"), "");
  ASSERT_TRUE(L.isOk()) << L.status().message();
  EXPECT_EQ(L->delimiter, ';');
  EXPECT_EQ(L->dataLines, 2u);
  test::writeText(d.file("b.pts"), "2\n1 2 3 9 10 20 30\n4 5 6 9 40 50 60\n");
  L = readTextLayout(d.file("b.pts"), "");
  ASSERT_TRUE(L.isOk());
  EXPECT_TRUE(L->hasColors);
  EXPECT_EQ(L->dataLines, 2u);
  test::writeText(d.file("c.xyz"), "1 2 3 4 5\n");
  EXPECT_FALSE(readTextLayout(d.file("c.xyz"), "").isOk());  // 5 columns: ambiguous
  L = readTextLayout(d.file("c.xyz"), "_,x,y,z,_");
  ASSERT_TRUE(L.isOk());
  test::writeText(d.file("e.xyz"), "1 2 3\n4 5 six\n");
  L = readTextLayout(d.file("e.xyz"), "");
  ASSERT_TRUE(L.isOk());
  struct Null : BatchSink {
    Status onPoints(const PointBatch&) override { return Status::ok(); }
  } sink;
  Status s = readText(d.file("e.xyz"), *L, 1024, sink);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("e.xyz:2: column 3"), std::string::npos) << s.message();
}

// The same cloud in PLY, XYZ, CSV (with a header) and PTS packs to the same cells.
TEST(Text, SameCloudInEveryTextFormatPacksTheSame) {
  test::TempDir d;
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(8000, 1.0, Eigen::Vector3d(10, 20, 30), pts, nrm);
  test::writePointsPly(d.file("s.ply"), pts, &nrm);
  std::ofstream xyz(d.file("s.xyz")), csv(d.file("s.csv")), ptsf(d.file("s.pts"));
  csv << "x,y,z,nx,ny,nz\n";
  ptsf << pts.size() << "\n";
  char line[256];
  for (size_t i = 0; i < pts.size(); ++i) {
    std::snprintf(line, sizeof(line), "%.17g %.17g %.17g %.9g %.9g %.9g\n", pts[i].x(), pts[i].y(), pts[i].z(),
                  nrm[i].x(), nrm[i].y(), nrm[i].z());
    xyz << line;
    ptsf << line;
    std::snprintf(line, sizeof(line), "%.17g,%.17g,%.17g,%.9g,%.9g,%.9g\n", pts[i].x(), pts[i].y(), pts[i].z(),
                  nrm[i].x(), nrm[i].y(), nrm[i].z());
    csv << line;
  }
  xyz.close();
  csv.close();
  ptsf.close();
  std::vector<PackSummary> sums;
  for (const char* f : {"s.ply", "s.xyz", "s.csv", "s.pts"}) {
    auto in = InputSet::open({d.file(f)}, std::string(f) == "s.csv" ? "" : (std::string(f) == "s.ply" ? "" : "x,y,z,nx,ny,nz"));
    ASSERT_TRUE(in.isOk()) << f << ": " << in.status().message();
    PackSummary s;
    ASSERT_TRUE(packInput(*in, d.file(std::string(f) + ".hfa"), PackOptions{}, nullptr, s).isOk()) << f;
    EXPECT_FALSE(s.normalsEstimated) << f;
    sums.push_back(s);
  }
  for (size_t i = 1; i < sums.size(); ++i) {
    EXPECT_EQ(sums[i].pointsRead, sums[0].pointsRead);
    EXPECT_EQ(sums[i].cells, sums[0].cells);
    EXPECT_EQ(sums[i].texels, sums[0].texels);
  }
}

}  // namespace
}  // namespace sa

namespace sa {
namespace {

// A subdivided octahedron on the unit sphere (closed, genus 0).
void sphereMesh(int levels, std::vector<Eigen::Vector3d>& v, std::vector<std::array<int, 3>>& f) {
  v = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  f = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto m = [&](int a, int b) {
      auto k = std::minmax(a, b);
      auto it = mid.find(k);
      if (it != mid.end()) return it->second;
      v.push_back((v[size_t(a)] + v[size_t(b)]).normalized());
      return mid[k] = int(v.size()) - 1;
    };
    std::vector<std::array<int, 3>> g;
    for (auto& t : f) {
      const int a = m(t[0], t[1]), b = m(t[1], t[2]), c = m(t[2], t[0]);
      g.push_back({t[0], a, c});
      g.push_back({t[1], b, a});
      g.push_back({t[2], c, b});
      g.push_back({a, b, c});
    }
    f = g;
  }
}

// The same mesh as PLY, OBJ, OFF and STL (OpenMesh reads the last three) packs to the same cells.
TEST(Mesh, SameMeshInPlyObjOffStlPacksTheSame) {
  test::TempDir d;
  std::vector<Eigen::Vector3d> v;
  std::vector<std::array<int, 3>> f;
  sphereMesh(4, v, f);
  std::ofstream ply(d.file("m.ply")), obj(d.file("m.obj")), off(d.file("m.off")), stl(d.file("m.stl"));
  ply.precision(17);
  obj.precision(17);
  off.precision(17);
  stl.precision(17);
  ply << "ply\nformat ascii 1.0\nelement vertex " << v.size() << "\nproperty double x\nproperty double y\nproperty double z\n"
      << "element face " << f.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
  off << "OFF\n" << v.size() << " " << f.size() << " 0\n";
  stl << "solid m\n";
  for (auto& p : v) {
    ply << p.x() << " " << p.y() << " " << p.z() << "\n";
    obj << "v " << p.x() << " " << p.y() << " " << p.z() << "\n";
    off << p.x() << " " << p.y() << " " << p.z() << "\n";
  }
  for (auto& t : f) {
    ply << "3 " << t[0] << " " << t[1] << " " << t[2] << "\n";
    obj << "f " << t[0] + 1 << " " << t[1] + 1 << " " << t[2] + 1 << "\n";
    off << "3 " << t[0] << " " << t[1] << " " << t[2] << "\n";
    const Eigen::Vector3d n = (v[size_t(t[1])] - v[size_t(t[0])]).cross(v[size_t(t[2])] - v[size_t(t[0])]).normalized();
    stl << "facet normal " << n.x() << " " << n.y() << " " << n.z() << "\nouter loop\n";
    for (int k = 0; k < 3; ++k) stl << "vertex " << v[size_t(t[k])].x() << " " << v[size_t(t[k])].y() << " " << v[size_t(t[k])].z() << "\n";
    stl << "endloop\nendfacet\n";
  }
  stl << "endsolid m\n";
  ply.close();
  obj.close();
  off.close();
  stl.close();
  std::vector<PackSummary> sums;
  for (const char* name : {"m.ply", "m.obj", "m.off", "m.stl"}) {
    auto in = InputSet::open({d.file(name)});
    ASSERT_TRUE(in.isOk()) << name << ": " << in.status().message();
    EXPECT_TRUE(in->hasTriangles()) << name;
    PackSummary s;
    ASSERT_TRUE(packInput(*in, d.file(std::string(name) + ".hfa"), PackOptions{}, nullptr, s).isOk()) << name;
    EXPECT_TRUE(s.fromTriangles) << name;
    std::printf("%s: %llu vertices, %llu triangles -> %u cells, %llu texels\n", name, (unsigned long long)s.pointsRead,
                (unsigned long long)s.triangles, s.cells, (unsigned long long)s.texels);
    sums.push_back(s);
  }
  for (size_t i = 1; i < sums.size(); ++i) {
    EXPECT_EQ(sums[i].triangles, sums[0].triangles);
    EXPECT_EQ(sums[i].pointsRead, sums[0].pointsRead);  // STL's repeated corners are welded by OpenMesh
    EXPECT_EQ(sums[i].cells, sums[0].cells);
  }
}

}  // namespace
}  // namespace sa

namespace sa {
namespace {

// OpenMesh reserves an OFF header's counts before reading (2*10^9 vertices aborted with
// bad_alloc); the counts are checked against the file size first. A malformed OBJ that makes
// OpenMesh abort on an assertion is an error here, because OpenMesh runs in a child process.
TEST(Mesh, HostileOffCountsAndAbortingObjAreBadInput) {
  test::TempDir d;
  test::writeText(d.file("h.off"), "OFF\n2000000000 2000000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  auto h = InputSet::open({d.file("h.off")});
  ASSERT_FALSE(h.isOk());
  EXPECT_EQ(h.status().kind(), ErrorKind::kBadInput);
  EXPECT_NE(h.status().message().find("OFF header declares 2000000000 vertices"), std::string::npos) << h.status().message();
  // `f` with no vertex indices: OpenMesh 9's OBJ reader asserts (!vhandles.empty()).
  test::writeText(d.file("a.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf /1\n");
  auto a = InputSet::open({d.file("a.obj")});
  ASSERT_FALSE(a.isOk());
  EXPECT_EQ(a.status().kind(), ErrorKind::kBadInput);
  EXPECT_NE(a.status().message().find("a.obj"), std::string::npos) << a.status().message();
  // And a good mesh still reads afterwards, through the same child-process path.
  test::writeText(d.file("g.off"), "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  auto g = InputSet::open({d.file("g.off")});
  ASSERT_TRUE(g.isOk()) << g.status().message();
  EXPECT_EQ(g->pointCount(), 3u);
  EXPECT_TRUE(g->hasTriangles());
}

}  // namespace
}  // namespace sa
