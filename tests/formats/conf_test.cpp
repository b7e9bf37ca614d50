#include "formats/conf.h"

#include <flann/flann.hpp>
#include <gtest/gtest.h>

#include <algorithm>

#include "../common/test_util.h"
#include "formats/ply.h"
#include "formats/source.h"

namespace sa {
namespace {

struct Collect : BatchSink {
  std::vector<double> xyz;
  std::vector<uint16_t> scan;
  Status onPoints(const PointBatch& b) override {
    for (size_t i = 0; i < b.size(); ++i) {
      xyz.insert(xyz.end(), {b.x[i], b.y[i], b.z[i]});
      scan.push_back(b.scan.empty() ? 0 : b.scan[i]);
    }
    return Status::ok();
  }
};

TEST(Conf, ParsesBmeshAndIgnoresCameraAndMesh) {
  test::TempDir d;
  test::writeText(d.file("s.conf"),
                  "camera 0 0 0 0 0 0 1\nmesh other 1 2 3 0 0 0 1\nbmesh a.ply 1 2 3 0 0 0.7071068 0.7071068\n");
  auto scans = readConf(d.file("s.conf"));
  ASSERT_TRUE(scans.isOk()) << scans.status().message();
  ASSERT_EQ(scans->size(), 1u);
  const ScanEntry& e = (*scans)[0];
  EXPECT_EQ(e.path, d.file("a.ply"));
  // q = 90° about z; p' = R^T p + t maps x to -y.
  const Eigen::Vector3d p = e.rotation * Eigen::Vector3d(1, 0, 0) + e.translation;
  EXPECT_NEAR(p.x(), 1, 1e-6);
  EXPECT_NEAR(p.y(), 1, 1e-6);
  EXPECT_NEAR(p.z(), 3, 1e-6);
}

TEST(Conf, ErrorsNameFileAndLine) {
  test::TempDir d;
  test::writeText(d.file("bad.conf"), "camera 0 0 0 0 0 0 1\nbmesh a.ply 1 2 x 0 0 0 1\n");
  auto scans = readConf(d.file("bad.conf"));
  ASSERT_FALSE(scans.isOk());
  EXPECT_NE(scans.status().message().find("bad.conf:2"), std::string::npos) << scans.status().message();
}

// The aligned raw scans must land on Stanford's own reconstruction.
TEST(ConfReal, BunnyScansAlignWithinOneMillimetre) {
  auto input = InputSet::open({test::sharedData("stanford_bunny/scans/bun.conf")});
  ASSERT_TRUE(input.isOk()) << input.status().message();
  EXPECT_EQ(input->files().size(), 10u);
  Collect c;
  ASSERT_TRUE(input->stream(c, false).isOk());
  EXPECT_EQ(c.scan.size(), 362272u);
  Collect ref;
  ASSERT_TRUE(readPly(test::sharedData("stanford_bunny/reconstruction/bun_zipper.ply"), {}, ref).isOk());
  flann::Matrix<double> data(ref.xyz.data(), ref.xyz.size() / 3, 3);
  flann::Index<flann::L2_Simple<double>> index(data, flann::KDTreeSingleIndexParams(10));
  index.buildIndex();
  // Per scan: median distance of every 20th point to the nearest reconstruction vertex.
  for (uint16_t s = 0; s < 10; ++s) {
    std::vector<double> q;
    for (size_t i = 0; i < c.scan.size(); i += 20)
      if (c.scan[i] == s) q.insert(q.end(), {c.xyz[3 * i], c.xyz[3 * i + 1], c.xyz[3 * i + 2]});
    const size_t m = q.size() / 3;
    ASSERT_GT(m, 100u);
    std::vector<int> ind(m);
    std::vector<double> dist(m);
    flann::Matrix<int> mi(ind.data(), m, 1);
    flann::Matrix<double> md(dist.data(), m, 1);
    flann::Matrix<double> mq(q.data(), m, 3);
    index.knnSearch(mq, mi, md, 1, flann::SearchParams(flann::FLANN_CHECKS_UNLIMITED));
    std::nth_element(dist.begin(), dist.begin() + m / 2, dist.end());
    const double median = std::sqrt(dist[m / 2]);
    EXPECT_LT(median, 1e-3) << input->files()[s].path;
    std::printf("scan %s: median distance to bun_zipper %.3f mm\n", input->files()[s].path.c_str(), median * 1e3);
  }
}

}  // namespace
}  // namespace sa
