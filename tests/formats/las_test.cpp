#include "formats/las.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>

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
