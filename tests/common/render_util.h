// GPU-vs-CPU comparison helpers for the viewer and stress tests.
#pragma once
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "atlas/raycast.h"
#include "preprocess/pipeline.h"
#include "test_util.h"
#include "viewer/camera.h"
#include "viewer/egl_context.h"

namespace sa::test {

// A fixture with one headless GL context for the whole test suite.
class GlTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    ctx_ = new EglContext;
    Status s = ctx_->init();
    ASSERT_TRUE(s.isOk()) << s.message();
  }
  static void TearDownTestSuite() {
    delete ctx_;
    ctx_ = nullptr;
  }
  static inline EglContext* ctx_ = nullptr;
};

// Linear depth of the CPU reference ray cast for every pixel (+inf on a miss).
inline std::vector<float> cpuDepth(const PackReader& p, const Camera& cam) {
  CpuRaycaster rc(p);
  const Eigen::Vector3d origin(p.meta().origin);
  std::vector<float> d(size_t(cam.width) * cam.height, INFINITY);
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Eigen::Vector3d dir = cam.rayDirection(x + 0.5, y + 0.5);
      RayHit h = rc.cast(cam.eye - origin, dir);
      if (h.hit) d[size_t(y) * cam.width + x] = float(h.t * dir.dot(cam.forward()));
    }
  return d;
}

struct Agreement {
  size_t covered = 0, agree = 0, coverageDiffers = 0;
  double maxErr = 0, p99Err = 0;  // over pixels both cover, absolute
};

inline Agreement agreement(const std::vector<float>& gpu, const std::vector<float>& cpu, double tol) {
  Agreement a;
  std::vector<double> errs;
  for (size_t i = 0; i < gpu.size(); ++i) {
    const bool g = std::isfinite(gpu[i]), c = std::isfinite(cpu[i]);
    if (!g && !c) continue;
    ++a.covered;
    if (g != c) ++a.coverageDiffers;
    if (g && c) {
      const double e = std::abs(double(gpu[i]) - cpu[i]);
      errs.push_back(e);
      a.maxErr = std::max(a.maxErr, e);
      if (e <= tol) ++a.agree;
    }
  }
  if (!errs.empty()) {
    std::sort(errs.begin(), errs.end());
    a.p99Err = errs[std::min(errs.size() - 1, size_t(0.99 * double(errs.size())))];
  }
  return a;
}

// Packs points (with normals) written to dir/name.ply into dir/name.hfa.
inline std::string packPoints(const TempDir& dir, const std::vector<Eigen::Vector3d>& pts,
                              const std::vector<Eigen::Vector3d>& nrm, const std::string& name,
                              const PackOptions& opt = {}, PackSummary* summary = nullptr) {
  writePointsPly(dir.file(name + ".ply"), pts, &nrm);
  auto in = InputSet::open({dir.file(name + ".ply")});
  EXPECT_TRUE(in.isOk()) << (in.isOk() ? "" : in.status().message());
  PackSummary sum;
  Status s = packInput(*in, dir.file(name + ".hfa"), opt, nullptr, sum);
  EXPECT_TRUE(s.isOk()) << s.message();
  if (summary) *summary = sum;
  return dir.file(name + ".hfa");
}

}  // namespace sa::test
