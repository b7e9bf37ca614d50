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
