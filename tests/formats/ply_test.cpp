#include "formats/ply.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstring>

#include "../common/test_util.h"
#include "formats/source.h"

namespace sa {
namespace {

struct Collect : BatchSink {
  PointBatch all;
  std::vector<uint32_t> tris;
  size_t batches = 0;
  Status onPoints(const PointBatch& b) override {
    ++batches;
    for (size_t i = 0; i < b.size(); ++i) {
      all.x.push_back(b.x[i]); all.y.push_back(b.y[i]); all.z.push_back(b.z[i]);
      if (b.hasNormals()) { all.nx.push_back(b.nx[i]); all.ny.push_back(b.ny[i]); all.nz.push_back(b.nz[i]); }
      if (b.hasColors()) { all.r.push_back(b.r[i]); all.g.push_back(b.g[i]); all.b.push_back(b.b[i]); }
    }
    return Status::ok();
  }
  Status onTriangles(const uint32_t* idx, size_t n) override {
    tris.insert(tris.end(), idx, idx + 3 * n);
    return Status::ok();
  }
};

template <class T>
void put(std::vector<char>& out, T v, bool bigEndian) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (bigEndian) std::reverse(b, b + sizeof(T));
  out.insert(out.end(), b, b + sizeof(T));
}

// The same 3 vertices (with colours) and 1 quad face in the three encodings, with the
// properties in an unusual order and of mixed types, plus elements the reader must skip.
std::vector<char> binaryPly(bool big) {
  std::string h = std::string("ply\nformat ") + (big ? "binary_big_endian" : "binary_little_endian") +
                  " 1.0\ncomment test\nelement vertex 4\nproperty uchar red\nproperty double z\n"
                  "property float x\nproperty uchar green\nproperty int y\nproperty uchar blue\n"
                  "element range_grid 2\nproperty list uchar int vertex_indices\n"
                  "element face 1\nproperty list uchar int vertex_indices\nproperty float quality\nend_header\n";
  std::vector<char> out(h.begin(), h.end());
  const double zs[4] = {0.5, 1.5, 2.5, 3.5};
  for (int i = 0; i < 4; ++i) {
    put<uint8_t>(out, uint8_t(10 + i), big);
    put<double>(out, zs[i], big);
    put<float>(out, float(i) * 0.25f, big);
    put<uint8_t>(out, uint8_t(20 + i), big);
    put<int32_t>(out, -i, big);
    put<uint8_t>(out, uint8_t(30 + i), big);
  }
  put<uint8_t>(out, 1, big); put<int32_t>(out, 0, big);  // range_grid: one entry
  put<uint8_t>(out, 0, big);                              // range_grid: empty
  put<uint8_t>(out, 4, big);
  for (int i = 0; i < 4; ++i) put<int32_t>(out, i, big);
  put<float>(out, 1.0f, big);
  return out;
}

const char* kAscii =
    "ply\nformat ascii 1.0\nobj_info num_cols 2\nelement vertex 4\nproperty uchar red\nproperty double z\n"
    "property float x\nproperty uchar green\nproperty int y\nproperty uchar blue\n"
    "bye\nbye\n"
    "element range_grid 2\nproperty list uchar int vertex_indices\n"
    "element face 1\nproperty list uchar int vertex_indices\nproperty float quality\nend_header\n"
    "10 0.5 0 20 0 30\n11 1.5 0.25 21 -1 31\n12 2.5 0.5 22 -2 32\n13 3.5 0.75 23 -3 33\n"
    "1 0\n0\n4 0 1 2 3 1.0\n";

void expectSample(const Collect& c) {
  ASSERT_EQ(c.all.size(), 4u);
  for (int i = 0; i < 4; ++i) {
    EXPECT_DOUBLE_EQ(c.all.x[i], i * 0.25);
    EXPECT_DOUBLE_EQ(c.all.y[i], -i);
    EXPECT_DOUBLE_EQ(c.all.z[i], 0.5 + i);
    ASSERT_EQ(c.all.r.size(), 4u);
    EXPECT_EQ(c.all.r[i], 10 + i);
    EXPECT_EQ(c.all.g[i], 20 + i);
    EXPECT_EQ(c.all.b[i], 30 + i);
  }
  // The quad, fan-triangulated.
  EXPECT_EQ(c.tris, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3}));
}

TEST(Ply, AsciiWithUnknownHeaderLinesAndSkippedElements) {
  test::TempDir d;
  test::writeText(d.file("a.ply"), kAscii);
  Collect c;
  PlyHeader h;
  ASSERT_TRUE(readPly(d.file("a.ply"), {}, c, &h).isOk());
  expectSample(c);
  EXPECT_EQ(h.warnings.size(), 2u);  // the two 'bye' lines
  EXPECT_TRUE(h.hasColors);
  EXPECT_FALSE(h.hasNormals);
}

TEST(Ply, BinaryLittleAndBigEndianAnyPropertyOrder) {
  test::TempDir d;
  for (bool big : {false, true}) {
    test::writeBytes(d.file("b.ply"), binaryPly(big));
    Collect c;
    Status s = readPly(d.file("b.ply"), {}, c);
    ASSERT_TRUE(s.isOk()) << s.message();
    expectSample(c);
  }
}

TEST(Ply, StreamsInFixedBatches) {
  test::TempDir d;
  std::vector<Eigen::Vector3d> pts(1000, Eigen::Vector3d(1, 2, 3));
  test::writePointsPly(d.file("p.ply"), pts);
  Collect c;
  PlyReadOptions o;
  o.batchPoints = 64;
  ASSERT_TRUE(readPly(d.file("p.ply"), o, c).isOk());
  EXPECT_EQ(c.all.size(), 1000u);
  EXPECT_EQ(c.batches, 16u);  // ceil(1000 / 64)
}

TEST(Ply, TriangleStripsDecoded) {
  test::TempDir d;
  std::string h = "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
                  "element tristrips 1\nproperty list int int vertex_indices\nend_header\n"
                  "0 0 0\n1 0 0\n0 1 0\n1 1 0\n2 2 0\n"
                  "7 0 1 2 3 -1 2 4\n";
  test::writeText(d.file("s.ply"), h);
  Collect c;
  ASSERT_TRUE(readPly(d.file("s.ply"), {}, c).isOk());
  // Strip 0 1 2 3 -> (0,1,2), (2,1,3) with alternating winding; the strip after -1 has 2
  // indices only: no triangle.
  EXPECT_EQ(c.tris, (std::vector<uint32_t>{0, 1, 2, 2, 1, 3}));
}

// Range grids triangulate into 2 triangles per complete 2x2 block, 1 where one sample is
// missing, none where two are.
TEST(Ply, RangeGridTriangulation) {
  test::TempDir d;
  // 3 columns x 3 rows; grid cell (row 2, col 2) empty.
  test::writeText(d.file("g.ply"),
                  "ply\nformat ascii 1.0\nobj_info num_cols 3\nobj_info num_rows 3\nelement vertex 8\n"
                  "property float x\nproperty float y\nproperty float z\nelement range_grid 9\n"
                  "property list uchar int vertex_indices\nend_header\n"
                  "0 0 0\n1 0 0\n2 0 0\n0 1 0\n1 1 0\n2 1 0\n0 2 0\n1 2 0\n"
                  "1 0\n1 1\n1 2\n1 3\n1 4\n1 5\n1 6\n1 7\n0\n");
  Collect c;
  PlyReadOptions o;
  o.rangeGridTriangles = true;
  ASSERT_TRUE(readPly(d.file("g.ply"), o, c).isOk());
  // Blocks: (0,0) full -> 2, (0,1) full -> 2, (1,0) full -> 2, (1,1) missing one -> 1.
  EXPECT_EQ(c.tris.size() / 3, 7u);
  for (uint32_t v : c.tris) EXPECT_LT(v, 8u);
  Collect plain;
  ASSERT_TRUE(readPly(d.file("g.ply"), {}, plain).isOk());
  EXPECT_TRUE(plain.tris.empty());  // without the option the grid is skipped
}

TEST(PlyReal, BunnyRangeGridTriangulates) {
  Collect c;
  PlyReadOptions o;
  o.rangeGridTriangles = true;
  ASSERT_TRUE(readPly(test::sharedData("stanford_bunny/scans/bun000.ply"), o, c).isOk());
  EXPECT_EQ(c.all.size(), 40256u);
  // Nearly two triangles per sample on a dense range image.
  EXPECT_GT(c.tris.size() / 3, 70000u);
  EXPECT_LT(c.tris.size() / 3, 2u * 40256u);
}

TEST(Ply, TruncatedFileNamesTheByteOffset) {
  test::TempDir d;
  auto bytes = binaryPly(false);
  bytes.resize(bytes.size() - 30);
  test::writeBytes(d.file("t.ply"), bytes);
  Collect c;
  Status s = readPly(d.file("t.ply"), {}, c);
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.kind(), ErrorKind::kBadInput);
  EXPECT_NE(s.message().find("t.ply"), std::string::npos) << s.message();
}

TEST(Ply, HugeHeaderCountRejectedBeforeAllocating) {
  test::TempDir d;
  for (const char* fmt : {"binary_little_endian", "ascii"}) {
    std::string h = std::string("ply\nformat ") + fmt +
                    " 1.0\nelement vertex 1000000000000\nproperty float x\nproperty float y\nproperty float z\n"
                    "end_header\n";
    h += std::string(1000, '\0');
    test::writeText(d.file("h.ply"), h);
    Collect c;
    const auto t0 = std::chrono::steady_clock::now();
    Status s = readPly(d.file("h.ply"), {}, c);
    ASSERT_FALSE(s.isOk());
    EXPECT_NE(s.message().find("1000000000000 vertex"), std::string::npos) << s.message();
    EXPECT_EQ(c.all.size(), 0u);
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 1.0);
  }
}

TEST(Ply, MalformedNumberNamesLine) {
  test::TempDir d;
  test::writeText(d.file("m.ply"),
                  "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
                  "end_header\n1 2 3\n4 x5 6\n");
  Collect c;
  Status s = readPly(d.file("m.ply"), {}, c);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("m.ply:9"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("'x5'"), std::string::npos) << s.message();
}

TEST(Ply, FaceIndexOutOfRangeRejected) {
  test::TempDir d;
  test::writeText(d.file("f.ply"),
                  "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n");
  Collect c;
  Status s = readPly(d.file("f.ply"), {}, c);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("vertex 7"), std::string::npos) << s.message();
}

TEST(Ply, NotAPlyFile) {
  test::TempDir d;
  test::writeText(d.file("x.ply"), "hello\n");
  Collect c;
  Status s = readPly(d.file("x.ply"), {}, c);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("not a PLY file"), std::string::npos);
}

TEST(PlyReal, DragonScanWithByeLines) {
  Collect c;
  PlyHeader h;
  Status s = readPly(test::sharedData("stanford_dragon/scans_stand/dragonStandRight_0.ply"), {}, c, &h);
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_EQ(c.all.size(), 41841u);
  EXPECT_EQ(h.warnings.size(), 3u);   // three 'bye' lines, skipped with a warning
  EXPECT_TRUE(c.tris.empty());        // range_grid is skipped, not taken for faces
}

TEST(PlyReal, IgeaBinaryTriangleStrips) {
  Collect c;
  Status s = readPly(test::sharedData("igea/igea.ply"), {}, c);
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_EQ(c.all.size(), 134345u);
  EXPECT_EQ(c.tris.size() / 3, 268686u);  // PROVENANCE.md: 2V - 4 non-degenerate triangles
}

TEST(PlyReal, BunnyZipperMesh) {
  Collect c;
  Status s = readPly(test::sharedData("stanford_bunny/reconstruction/bun_zipper.ply"), {}, c);
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_EQ(c.all.size(), 35947u);
  EXPECT_EQ(c.tris.size() / 3, 69451u);
}

}  // namespace
}  // namespace sa
