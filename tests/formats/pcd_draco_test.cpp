// PCD (through PCL), Draco (in and out), the convert writers, and the same cloud in every
// format packing to the same cells.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>

#include "../common/test_util.h"
#include "formats/draco.h"
#include "formats/isolate.h"
#include "formats/mesh_openmesh.h"
#include "formats/pcd.h"
#include "formats/source.h"
#include "formats/writers.h"
#include "preprocess/pipeline.h"

namespace sa {
namespace {

struct Gather : BatchSink {
  PointBatch all;
  uint64_t batches = 0, triangles = 0;
  Status onPoints(const PointBatch& b) override {
    ++batches;
    all.x.insert(all.x.end(), b.x.begin(), b.x.end());
    all.y.insert(all.y.end(), b.y.begin(), b.y.end());
    all.z.insert(all.z.end(), b.z.begin(), b.z.end());
    all.nx.insert(all.nx.end(), b.nx.begin(), b.nx.end());
    all.r.insert(all.r.end(), b.r.begin(), b.r.end());
    all.g.insert(all.g.end(), b.g.begin(), b.g.end());
    all.b.insert(all.b.end(), b.b.begin(), b.b.end());
    all.intensity.insert(all.intensity.end(), b.intensity.begin(), b.intensity.end());
    all.confidence.insert(all.confidence.end(), b.confidence.begin(), b.confidence.end());
    all.classification.insert(all.classification.end(), b.classification.begin(), b.classification.end());
    return Status::ok();
  }
  Status onTriangles(const uint32_t*, size_t n) override {
    triangles += n;
    return Status::ok();
  }
};

// PROVENANCE.md: PCD v0.7 binary_compressed, organized 640x480, FIELDS x y z rgba,
// 307200 entries of which 209280 finite, z 0.69-2.59 m.
TEST(PcdReal, TableSceneMugOrganizedBinaryCompressed) {
  const std::string path = test::sharedData("pcd/table_scene_mug_stereo_textured.pcd");
  auto h = readPcdHeader(path);
  ASSERT_TRUE(h.isOk()) << h.status().message();
  EXPECT_EQ(h->encoding, PcdEncoding::kBinaryCompressed);
  EXPECT_EQ(h->width, 640u);
  EXPECT_EQ(h->height, 480u);
  EXPECT_EQ(h->points, 307200u);
  EXPECT_TRUE(h->organized());
  EXPECT_TRUE(h->hasColors);
  Gather g;
  uint64_t holes = 0;
  Status s = readPcd(path, 10000, g, &holes);
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_EQ(g.all.size(), 209280u);
  EXPECT_EQ(holes, 97920u);
  const auto [zlo, zhi] = std::minmax_element(g.all.z.begin(), g.all.z.end());
  EXPECT_NEAR(*zlo, 0.69, 0.005);
  EXPECT_NEAR(*zhi, 2.59, 0.005);
  // A textured scene: colours vary (not all white, not all black).
  std::map<int, int> reds;
  for (auto r : g.all.r) ++reds[r];
  EXPECT_GT(reds.size(), 100u);
  EXPECT_GT(g.batches, 20u);  // delivered in batches, not one block
}

// Writes `pts` as PCD in the given encoding (ascii or binary), x y z float + rgb packed + intensity.
void writePcd(const std::string& path, const std::vector<float>& xyz, bool binary, const std::string& extraHeader = "") {
  const size_t n = xyz.size() / 3;
  std::ofstream f(path, std::ios::binary);
  f << "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgb intensity\nSIZE 4 4 4 4 4\n"
       "TYPE F F F U F\nCOUNT 1 1 1 1 1\nWIDTH "
    << n << "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << n << "\n" << extraHeader << "DATA "
    << (binary ? "binary" : "ascii") << "\n";
  f.precision(9);
  for (size_t i = 0; i < n; ++i) {
    const uint32_t rgb = (uint32_t(i % 256) << 16) | (uint32_t((i / 7) % 256) << 8) | 77u;
    const float inten = float(i % 1000);
    if (binary) {
      f.write(reinterpret_cast<const char*>(&xyz[3 * i]), 12);
      f.write(reinterpret_cast<const char*>(&rgb), 4);
      f.write(reinterpret_cast<const char*>(&inten), 4);
    } else {
      if (std::isnan(xyz[3 * i])) f << "nan nan nan " << rgb << " " << inten << "\n";
      else f << xyz[3 * i] << " " << xyz[3 * i + 1] << " " << xyz[3 * i + 2] << " " << rgb << " " << inten << "\n";
    }
  }
}

TEST(Pcd, AsciiAndBinaryStreamInBatchesWithColourAndIntensity) {
  test::TempDir d;
  std::vector<float> xyz;
  for (int i = 0; i < 5000; ++i) {
    xyz.push_back(float(i % 100) * 0.01f);
    xyz.push_back(float(i / 100) * 0.01f);
    xyz.push_back(i == 17 ? NAN : 0.5f);
    if (i == 17) xyz[xyz.size() - 3] = xyz[xyz.size() - 2] = NAN;
  }
  writePcd(d.file("a.pcd"), xyz, false);
  writePcd(d.file("b.pcd"), xyz, true);
  for (const char* name : {"a.pcd", "b.pcd"}) {
    Gather g;
    uint64_t holes = 0;
    Status s = readPcd(d.file(name), 777, g, &holes);
    ASSERT_TRUE(s.isOk()) << name << ": " << s.message();
    EXPECT_EQ(g.all.size(), 4999u) << name;
    EXPECT_EQ(holes, 1u) << name;
    EXPECT_EQ(g.batches, 7u) << name;  // ceil(5000 / 777)
    ASSERT_EQ(g.all.intensity.size(), 4999u) << name;
    EXPECT_EQ(g.all.r[5], 5) << name;
    EXPECT_EQ(g.all.b[5], 77) << name;
    EXPECT_FLOAT_EQ(g.all.intensity[20], 21.0f) << name;  // index 21 in the file (17 was a hole)
    EXPECT_NEAR(g.all.x[3], 0.03, 1e-6) << name;
  }
}

TEST(Pcd, HostileHeadersAreRefusedBeforePclSeesThem) {
  test::TempDir d;
  auto expectError = [&](const std::string& text, const std::string& needle) {
    test::writeText(d.file("h.pcd"), text);
    auto h = readPcdHeader(d.file("h.pcd"));
    ASSERT_FALSE(h.isOk()) << needle;
    EXPECT_EQ(h.status().kind(), ErrorKind::kBadInput);
    EXPECT_NE(h.status().message().find(needle), std::string::npos) << h.status().message();
    EXPECT_NE(h.status().message().find("h.pcd"), std::string::npos) << h.status().message();
  };
  const std::string head = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n";
  // 10^12 points in a tiny file: refused from the header (PCL would allocate 12 TB).
  expectError(head + "WIDTH 1000000000000\nHEIGHT 1\nPOINTS 1000000000000\nDATA binary\n", "more than PCL");
  expectError(head + "WIDTH 4000000\nHEIGHT 1\nPOINTS 4000000\nDATA binary\n0000", "body has only");
  expectError(head + "WIDTH 4000000\nHEIGHT 1\nPOINTS 4000000\nDATA ascii\n1 2 3\n", "ascii body has only");
  expectError(head + "WIDTH 10\nHEIGHT 2\nPOINTS 21\nDATA ascii\n", "is not POINTS");
  expectError("VERSION 0.7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2\n", "x, y and z");
  expectError("FIELDS x y z\nSIZE 4 4 3\n", "expected 1, 2, 4 or 8");
  expectError("FIELDS x y z\nSIZE 4 4 4\nTYPE F F Q\n", "expected I, U or F");
  expectError("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 0\n", "COUNT of field 'z'");
  expectError(head + "WIDTH 1\nPOINTS 1\nDATA lzma\n", "unknown DATA encoding");
  expectError(head + "WIDTH 1\nPOINTS 1\n", "ends before its DATA line");
  expectError("ply\nformat ascii 1.0\n", "not a PCD file");
  expectError("", "empty file");
  // binary_compressed: sizes in the 8-byte prefix must fit the file and the header.
  auto compressed = [&](uint32_t csize, uint32_t usize, size_t bodyBytes) {
    std::string t = head + "WIDTH 100\nHEIGHT 1\nPOINTS 100\nDATA binary_compressed\n";
    t.append(reinterpret_cast<const char*>(&csize), 4);
    t.append(reinterpret_cast<const char*>(&usize), 4);
    t.append(bodyBytes, '\0');
    return t;
  };
  expectError(compressed(5000, 1200, 100), "runs past the end");
  expectError(compressed(50, 4000000000u, 100), "decompresses to");
  expectError(compressed(4, 1200, 100), "cannot hold");
  // Bodies: malformed ascii numbers name line and column; short files name the point.
  test::writeText(d.file("m.pcd"), head + "WIDTH 3\nPOINTS 3\nDATA ascii\n1 2 3\n4 5 x6\n7 8 9\n");
  Gather g;
  Status s = readPcd(d.file("m.pcd"), 100, g);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("m.pcd:10: column 3"), std::string::npos) << s.message();
  test::writeText(d.file("c.pcd"), head + "WIDTH 3\nPOINTS 3\nDATA ascii\n1 2 3\n4 5\n7 8 9\n\n\n\n\n");
  s = readPcd(d.file("c.pcd"), 100, g);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("c.pcd:10: expected 3 values, found 2"), std::string::npos) << s.message();
  // A corrupt LZF block of a consistent size is reported, not trusted.
  test::writeText(d.file("z.pcd"), compressed(100, 1200, 100));
  s = readPcd(d.file("z.pcd"), 100, g);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("LZF"), std::string::npos) << s.message();
}

// LAS attributes survive LAS -> Draco -> read back; georeferenced positions within the
// quantization step of the original.
TEST(DracoReal, AutzenRoundTripKeepsAttributesAndGeoreference) {
  auto in = InputSet::open({test::sharedData("lidar/autzen_trim.las")});
  ASSERT_TRUE(in.isOk()) << in.status().message();
  Gather orig;
  ASSERT_TRUE(in->stream(orig, false).isOk());
  test::TempDir d;
  for (int bits : {16, 0}) {
    DracoWriteOptions o;
    o.positionBits = bits;
    DracoWriter w(o);
    ASSERT_TRUE(in->stream(w, false).isOk());
    bool shifted = false;
    auto bytes = w.write(d.file("a.drc"), &shifted);
    ASSERT_TRUE(bytes.isOk()) << bytes.status().message();
    EXPECT_TRUE(shifted);
    EXPECT_LT(*bytes, bits ? 3742038u / 2 : 3742038u) << bits;  // under the LAS file
    auto info = readDracoInfo(d.file("a.drc"));
    ASSERT_TRUE(info.isOk()) << info.status().message();
    EXPECT_TRUE(info->hasColors && info->hasIntensity && info->hasClassification && info->shifted);
    Gather back;
    ASSERT_TRUE(readDraco(d.file("a.drc"), 4096, false, back).isOk());
    ASSERT_EQ(back.all.size(), 110000u);
    ASSERT_EQ(back.all.classification.size(), 110000u);
    // Draco keeps point order for point clouds without deduplication.
    const double step = bits ? 1177.46 / ((1 << bits) - 1) : 1e-3;
    double maxErr = 0;
    std::map<int, int> classes;
    for (size_t i = 0; i < back.all.size(); ++i) {
      maxErr = std::max({maxErr, std::abs(back.all.x[i] - orig.all.x[i]), std::abs(back.all.y[i] - orig.all.y[i]),
                         std::abs(back.all.z[i] - orig.all.z[i])});
      ++classes[back.all.classification[i]];
      ASSERT_EQ(back.all.intensity[i], orig.all.intensity[i]) << i;
      ASSERT_EQ(back.all.r[i], orig.all.r[i]) << i;
    }
    EXPECT_LT(maxErr, step) << bits;
    EXPECT_EQ(classes[1], 83893);
    EXPECT_EQ(classes[2], 26107);
  }
}

// A mesh stays a mesh through Draco and packs through the triangle path like the PLY.
TEST(DracoReal, BunnyMeshRoundTripPacksLikeThePly) {
  test::TempDir d;
  auto ply = InputSet::open({test::sharedData("stanford_bunny/reconstruction/bun_zipper.ply")});
  ASSERT_TRUE(ply.isOk());
  DracoWriter w(DracoWriteOptions{});
  ASSERT_TRUE(ply->stream(w, true).isOk());
  EXPECT_EQ(w.triangles(), 69451u);
  ASSERT_TRUE(w.write(d.file("b.drc")).isOk());
  auto drc = InputSet::open({d.file("b.drc")});
  ASSERT_TRUE(drc.isOk()) << drc.status().message();
  EXPECT_TRUE(drc->hasTriangles());
  EXPECT_TRUE(drc->allHaveIntensity() && drc->allHaveConfidence());
  PackSummary a, b;
  ASSERT_TRUE(packInput(*ply, d.file("p.hfa"), PackOptions{}, nullptr, a).isOk());
  Status s = packInput(*drc, d.file("d.hfa"), PackOptions{}, nullptr, b);
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_TRUE(b.fromTriangles);
  EXPECT_EQ(b.triangles, a.triangles);
  EXPECT_NEAR(double(b.cells), double(a.cells), 0.02 * a.cells);
}

TEST(Draco, BadFilesGiveClearErrors) {
  test::TempDir d;
  test::writeText(d.file("n.drc"), "PLY not draco");
  auto r = readDracoInfo(d.file("n.drc"));
  ASSERT_FALSE(r.isOk());
  EXPECT_NE(r.status().message().find("not a Draco file"), std::string::npos);
  // A valid file cut short.
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(2000, 1.0, Eigen::Vector3d(0, 0, 0), pts, nrm);
  test::writePointsPly(d.file("s.ply"), pts, &nrm);
  auto in = InputSet::open({d.file("s.ply")});
  ASSERT_TRUE(in.isOk());
  DracoWriter w(DracoWriteOptions{});
  ASSERT_TRUE(in->stream(w, false).isOk());
  auto bytes = w.write(d.file("s.drc"));
  ASSERT_TRUE(bytes.isOk());
  std::ifstream f(d.file("s.drc"), std::ios::binary);
  std::vector<char> all((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  all.resize(all.size() / 2);
  test::writeBytes(d.file("t.drc"), all);
  auto t = InputSet::open({d.file("t.drc")});
  ASSERT_FALSE(t.isOk());
  EXPECT_EQ(t.status().kind(), ErrorKind::kBadInput);
  EXPECT_NE(t.status().message().find("t.drc"), std::string::npos) << t.status().message();
}

// Fuzzing finding (fuzz_draco, out-of-memory): 39 bytes declaring 1090519044 points made
// Draco allocate about 13 GB before reading a point. Refused from the declared count now.
TEST(Draco, FuzzFindingHugeDeclaredPointCountRefusedBeforeDecoding) {
  const unsigned char bytes[] = {0x44, 0x52, 0x41, 0x43, 0x4f, 0x2, 0x3, 0x0, 0x0, 0x0, 0x0, 0x4, 0x0, 0x0, 0x41, 0x1,
                                 0x1, 0x0, 0x9, 0x1, 0x0, 0x0, 0x0, 0x0, 0x80, 0x3f, 0x0, 0x0, 0x64, 0x0, 0x0, 0x0,
                                 0x0, 0x0, 0x0, 0x0, 0x0, 0x0, 0x0};
  test::TempDir d;
  test::writeBytes(d.file("oom.drc"), std::vector<char>(bytes, bytes + sizeof(bytes)));
  auto r = readDracoInfo(d.file("oom.drc"));
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().kind(), ErrorKind::kBadInput);
  EXPECT_NE(r.status().message().find("declares 1090519044 points in a 39-byte file"), std::string::npos)
      << r.status().message();
}

// Fuzzing finding (fuzz_draco, out-of-memory): 29 bytes declaring 117 points, for which
// libdraco's kd-tree attribute decoder allocates 8 GB. No header check sees it; the decoder
// runs in a child process under a memory limit and its failure is a clear error here.
TEST(Draco, FuzzFindingDecoderAllocationIsContainedInTheChild) {
  const unsigned char bytes[] = {0x44, 0x52, 0x41, 0x43, 0x4f, 0x02, 0x00, 0x00, 0x01, 0x00, 0x00, 0x75, 0x00, 0x00, 0x00, 0x01, 0x01, 0x00, 0x05, 0x01, 0x41, 0x09, 0x01, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f};
  test::TempDir d;
  test::writeBytes(d.file("oom2.drc"), std::vector<char>(bytes, bytes + sizeof(bytes)));
  auto r = readDracoInfo(d.file("oom2.drc"));
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().kind(), ErrorKind::kBadInput);
  EXPECT_NE(r.status().message().find("oom2.drc"), std::string::npos) << r.status().message();
  // Still usable afterwards: a good file decodes in the same process.
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(500, 1.0, Eigen::Vector3d(0, 0, 0), pts, nrm);
  test::writePointsPly(d.file("s.ply"), pts, &nrm);
  auto in = InputSet::open({d.file("s.ply")});
  ASSERT_TRUE(in.isOk());
  DracoWriter w(DracoWriteOptions{});
  ASSERT_TRUE(in->stream(w, false).isOk());
  ASSERT_TRUE(w.write(d.file("s.drc")).isOk());
  Gather g;
  ASSERT_TRUE(readDraco(d.file("s.drc"), 100, false, g).isOk());
  EXPECT_EQ(g.all.size(), 500u);
  EXPECT_EQ(g.batches, 5u);
}

// Every input the fuzzers found (fuzz/regressions/<target>/) is refused as bad input, with
// the file named, in this process (the Draco ones through the child-process decoder).
TEST(FuzzRegressions, EveryStoredFindingIsABadInputError) {
  int n = 0;
  for (const auto& dir : std::filesystem::directory_iterator(std::string(SA_SOURCE_DIR) + "/fuzz/regressions")) {
    if (dir.path().filename() == "pack") continue;  // pack reader findings: pack_test
    for (const auto& f : std::filesystem::directory_iterator(dir.path())) {
      ++n;
      const std::string path = f.path().string();
      auto in = InputSet::open({path});
      Status s = in.isOk() ? Status::ok() : in.status();
      if (in.isOk()) {
        Gather g;
        s = in->stream(g, true);
      }
      ASSERT_FALSE(s.isOk()) << path;
      EXPECT_EQ(s.kind(), ErrorKind::kBadInput) << path << ": " << s.message();
      EXPECT_NE(s.message().find(f.path().filename().string()), std::string::npos) << s.message();
    }
  }
  EXPECT_GE(n, 4);
}

// Draco and OBJ/OFF/STL are decoded whole by their libraries; InputSet decodes them once, in
// open(), and replays a recording for every later pass. Proof: the file is deleted after open()
// and stream() still delivers every point and triangle, twice. Without the recording (size cap
// of 0 MiB) stream() decodes again and then fails on the deleted file.
TEST(DracoReal, DecodedOnceThenReplayedForEveryPass) {
  test::TempDir d;
  auto ply = InputSet::open({test::sharedData("stanford_bunny/reconstruction/bun_zipper.ply")});
  ASSERT_TRUE(ply.isOk());
  Gather ref;
  ASSERT_TRUE(ply->stream(ref, true).isOk());
  DracoWriter w(DracoWriteOptions{});
  ASSERT_TRUE(ply->stream(w, true).isOk());
  ASSERT_TRUE(w.write(d.file("b.drc")).isOk());
  {  // an OBJ of the same mesh
    std::ofstream obj(d.file("b.obj"));
    obj.precision(9);
    for (size_t i = 0; i < ref.all.x.size(); ++i) obj << "v " << ref.all.x[i] << " " << ref.all.y[i] << " " << ref.all.z[i] << "\n";
    struct Tris : BatchSink {
      std::vector<uint32_t> t;
      Status onPoints(const PointBatch&) override { return Status::ok(); }
      Status onTriangles(const uint32_t* idx, size_t n) override {
        t.insert(t.end(), idx, idx + 3 * n);
        return Status::ok();
      }
    } tris;
    ASSERT_TRUE(ply->stream(tris, true).isOk());
    for (size_t i = 0; i < tris.t.size(); i += 3) obj << "f " << tris.t[i] + 1 << " " << tris.t[i + 1] + 1 << " " << tris.t[i + 2] + 1 << "\n";
  }
  for (const char* name : {"b.drc", "b.obj"}) {
    // What a decode of the file delivers (Draco merges the mesh's duplicate vertices).
    Gather direct;
    const bool isDraco = std::string(name).ends_with(".drc");
    ASSERT_TRUE((isDraco ? readDraco(d.file(name), kDefaultBatchPoints, true, direct)
                         : readMesh(d.file(name), kDefaultBatchPoints, true, direct)).isOk());
    EXPECT_GT(direct.all.x.size(), 34000u) << name;
    EXPECT_GT(direct.triangles, 69000u) << name;
    auto in = InputSet::open({d.file(name)});
    ASSERT_TRUE(in.isOk()) << in.status().message();
    EXPECT_EQ(in->pointCount(), direct.all.x.size()) << name;
    ASSERT_TRUE(in->hasTriangles()) << name;
    ASSERT_TRUE(std::filesystem::remove(d.file(name)));
    for (int pass = 0; pass < 2; ++pass) {
      Gather g;
      Status s = in->stream(g, true);
      ASSERT_TRUE(s.isOk()) << name << ": " << s.message();
      EXPECT_EQ(g.all.x, direct.all.x) << name;
      EXPECT_EQ(g.all.z, direct.all.z) << name;
      EXPECT_EQ(g.triangles, direct.triangles) << name;
      Gather noTris;
      ASSERT_TRUE(in->stream(noTris, false).isOk());
      EXPECT_EQ(noTris.triangles, 0u) << name;
      EXPECT_EQ(noTris.all.y, direct.all.y) << name;
    }
  }
  ASSERT_TRUE(w.write(d.file("c.drc")).isOk());
  ::setenv("SA_RECORDING_MAX_MB", "0", 1);
  auto in = InputSet::open({d.file("c.drc")});
  ::unsetenv("SA_RECORDING_MAX_MB");
  ASSERT_TRUE(in.isOk()) << in.status().message();
  EXPECT_GT(in->pointCount(), 34000u);  // the counts do not need the recording
  Gather again;
  ASSERT_TRUE(in->stream(again, true).isOk());  // decoded again
  EXPECT_EQ(again.all.x.size(), in->pointCount());
  EXPECT_GT(again.triangles, 69000u);
  ASSERT_TRUE(std::filesystem::remove(d.file("c.drc")));
  Gather gone;
  Status s = in->stream(gone, true);
  EXPECT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("c.drc"), std::string::npos) << s.message();
}

// A reader that loops (as a hostile file could make libdraco or OpenMesh do) is stopped by the
// child's CPU-time limit and reported as bad input naming the file, instead of hanging pack.
TEST(Isolate, LoopingReaderIsStoppedByTheCpuLimit) {
  test::TempDir d;
  test::writeBytes(d.file("loop.obj"), std::vector<char>(100, 'v'));
  ::setenv("SA_READER_CPU_S", "1", 1);
  EXPECT_EQ(readerCpuLimitSeconds(d.file("loop.obj")), 1u);
  Status s = runIsolated(
      d.file("loop.obj"), 1ull << 30,
      [](BatchSink&, std::string&) {
        volatile uint64_t x = 0;
        for (;;) x = x + 1;
        return Status::ok();
      },
      nullptr, nullptr);
  ::unsetenv("SA_READER_CPU_S");
  ASSERT_FALSE(s.isOk());
  EXPECT_EQ(s.kind(), ErrorKind::kBadInput);
  EXPECT_NE(s.message().find("loop.obj"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("s of CPU time"), std::string::npos) << s.message();
  // Without the override: 2 minutes plus 4 s per MiB.
  EXPECT_EQ(readerCpuLimitSeconds(d.file("loop.obj")), 120u);
}

// The same cloud written by the converters in PLY, XYZ, CSV, PCD (ascii and binary) and
// lossless Draco packs to the same cells.
TEST(Formats, SameCloudInEveryFormatPacksTheSame) {
  test::TempDir d;
  std::vector<Eigen::Vector3d> pts, nrm;
  test::spherePoints(6000, 1.0, Eigen::Vector3d(1, 2, 3), pts, nrm);
  PointBatch b;
  for (size_t i = 0; i < pts.size(); ++i) {
    // Float-exact coordinates, so every format (PCD and Draco store floats) holds the same values.
    b.x.push_back(double(float(pts[i].x())));
    b.y.push_back(double(float(pts[i].y())));
    b.z.push_back(double(float(pts[i].z())));
    b.intensity.push_back(float(i % 500));
  }
  PointLayout layout;
  layout.intensity = true;
  {
    auto w = openPlyWriter(d.file("c.ply"), layout);
    ASSERT_TRUE(w.isOk());
    ASSERT_TRUE((*w)->onPoints(b).isOk());
    ASSERT_TRUE((*w)->finish().isOk());
    EXPECT_EQ((*w)->written(), pts.size());
  }
  for (auto [name, delim] : {std::pair{"c.xyz", ' '}, std::pair{"c.csv", ','}}) {
    auto w = openTextWriter(d.file(name), layout, delim);
    ASSERT_TRUE(w.isOk());
    ASSERT_TRUE((*w)->onPoints(b).isOk());
    ASSERT_TRUE((*w)->finish().isOk());
  }
  std::vector<float> xyz;
  for (size_t i = 0; i < b.size(); ++i) {
    xyz.push_back(float(b.x[i]));
    xyz.push_back(float(b.y[i]));
    xyz.push_back(float(b.z[i]));
  }
  writePcd(d.file("a.pcd"), xyz, false);
  writePcd(d.file("b.pcd"), xyz, true);
  {
    DracoWriteOptions o;
    o.positionBits = 0;
    DracoWriter w(o);
    ASSERT_TRUE(w.onPoints(b).isOk());
    ASSERT_TRUE(w.write(d.file("c.drc")).isOk());
  }
  std::vector<PackSummary> sums;
  for (const char* f : {"c.ply", "c.xyz", "c.csv", "a.pcd", "b.pcd", "c.drc"}) {
    auto in = InputSet::open({d.file(f)});
    ASSERT_TRUE(in.isOk()) << f << ": " << in.status().message();
    EXPECT_EQ(in->pointCount(), pts.size()) << f;
    EXPECT_TRUE(in->allHaveIntensity()) << f;
    PackSummary s;
    Status st = packInput(*in, d.file(std::string(f) + ".hfa"), PackOptions{}, nullptr, s);
    ASSERT_TRUE(st.isOk()) << f << ": " << st.message();
    sums.push_back(s);
  }
  for (size_t i = 1; i < sums.size(); ++i) {
    EXPECT_EQ(sums[i].pointsRead, sums[0].pointsRead) << i;
    EXPECT_EQ(sums[i].cells, sums[0].cells) << i;
    EXPECT_EQ(sums[i].texels, sums[0].texels) << i;
  }
}

// PLY intensity/confidence (bun_zipper has both) and LAS intensity/classification come through
// InputSet; mixing a file without them drops them rather than inventing values.
TEST(AttributesReal, KeptWhenEveryInputHasThem) {
  auto z = InputSet::open({test::sharedData("stanford_bunny/reconstruction/bun_zipper.ply")});
  ASSERT_TRUE(z.isOk());
  EXPECT_TRUE(z->allHaveIntensity());
  EXPECT_TRUE(z->allHaveConfidence());
  Gather g;
  ASSERT_TRUE(z->stream(g, false).isOk());
  ASSERT_EQ(g.all.confidence.size(), 35947u);
  const auto [clo, chi] = std::minmax_element(g.all.confidence.begin(), g.all.confidence.end());
  EXPECT_GE(*clo, 0.0f);
  EXPECT_LE(*chi, 1.0f);
  EXPECT_GT(*chi, *clo);
  auto l = InputSet::open({test::sharedData("lidar/lone-star.las")});
  ASSERT_TRUE(l.isOk());
  Gather lg;
  ASSERT_TRUE(l->stream(lg, false).isOk());
  ASSERT_EQ(lg.all.intensity.size(), 518862u);
  EXPECT_EQ(*std::max_element(lg.all.intensity.begin(), lg.all.intensity.end()), 2744.0f);
  EXPECT_EQ(*std::max_element(lg.all.classification.begin(), lg.all.classification.end()), 0);
  auto mixed = InputSet::open({test::sharedData("stanford_bunny/reconstruction/bun_zipper.ply"),
                               test::sharedData("stanford_bunny/scans/bun000.ply")});
  ASSERT_TRUE(mixed.isOk());
  EXPECT_FALSE(mixed->allHaveIntensity());
  Gather mg;
  ASSERT_TRUE(mixed->stream(mg, false).isOk());
  EXPECT_TRUE(mg.all.intensity.empty());
}

}  // namespace
}  // namespace sa
