#include "preprocess/nearest.h"

#include <flann/flann.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace sa {

struct NearestSamples::Index {
  flann::Index<flann::L2_Simple<float>> tree;
  explicit Index(flann::Matrix<float> data) : tree(data, flann::KDTreeSingleIndexParams(15)) { tree.buildIndex(); }
};

NearestSamples::NearestSamples(std::vector<float> xyz) : xyz_(std::move(xyz)) {
  if (size() > 0) index_ = std::make_unique<Index>(flann::Matrix<float>(xyz_.data(), size(), 3));
}

NearestSamples::~NearestSamples() = default;

void NearestSamples::distances(const double* queries, size_t m, double* out) const {
  if (!index_) {
    std::fill(out, out + m, std::numeric_limits<double>::infinity());
    return;
  }
  tbb::parallel_for(tbb::blocked_range<size_t>(0, m, 4096), [&](const tbb::blocked_range<size_t>& r) {
    const size_t n = r.size();
    std::vector<float> q(3 * n);
    for (size_t i = 0; i < 3 * n; ++i) q[i] = float(queries[3 * r.begin() + i]);
    std::vector<int> ind(n);
    std::vector<float> dist(n);
    flann::Matrix<int> mi(ind.data(), n, 1);
    flann::Matrix<float> md(dist.data(), n, 1);
    flann::Matrix<float> mq(q.data(), n, 3);
    index_->tree.knnSearch(mq, mi, md, 1, flann::SearchParams(flann::FLANN_CHECKS_UNLIMITED));
    for (size_t i = 0; i < n; ++i) {
      const size_t k = r.begin() + i;
      if (ind[i] < 0) {
        out[k] = std::numeric_limits<double>::infinity();
        continue;
      }
      // The distance again in double: the kd-tree's float squared distance loses digits.
      const float* s = &xyz_[3 * size_t(ind[i])];
      const double dx = queries[3 * k] - s[0], dy = queries[3 * k + 1] - s[1], dz = queries[3 * k + 2] - s[2];
      out[k] = std::sqrt(dx * dx + dy * dy + dz * dz);
    }
  });
}

FarStats summarizeFar(const std::vector<double>& d) {
  FarStats s;
  s.pixels = d.size();
  if (d.empty()) return s;
  std::vector<double> v(d);
  auto at = [&](double q) {
    const size_t k = std::min(v.size() - 1, size_t(q * double(v.size() - 1) + 0.5));
    std::nth_element(v.begin(), v.begin() + long(k), v.end());
    return v[k];
  };
  s.median = at(0.5);
  s.p99 = at(0.99);
  size_t b3 = 0, b10 = 0;
  for (double x : d) {
    b3 += x > 3;
    b10 += x > 10;
  }
  s.beyond3 = double(b3) / double(d.size());
  s.beyond10 = double(b10) / double(d.size());
  return s;
}

}  // namespace sa
