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

void NearestSamples::distances(const double* queries, size_t m, double* out, uint32_t* nearest) const {
  if (!index_) {
    std::fill(out, out + m, std::numeric_limits<double>::infinity());
    if (nearest) std::fill(nearest, nearest + m, UINT32_MAX);
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
      if (nearest) nearest[k] = ind[i] < 0 ? UINT32_MAX : uint32_t(ind[i]);
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

std::vector<float> NearestSamples::areaSpacings() const {
  constexpr int kNeighbours = 8;
  const size_t n = size();
  std::vector<float> out(n, 0.f);
  if (!index_ || n <= size_t(kNeighbours)) return out;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& r) {
    const size_t m = r.size();
    std::vector<int> ind(m * (kNeighbours + 1));
    std::vector<float> dist(m * (kNeighbours + 1));
    flann::Matrix<int> mi(ind.data(), m, kNeighbours + 1);
    flann::Matrix<float> md(dist.data(), m, kNeighbours + 1);
    flann::Matrix<float> mq(const_cast<float*>(&xyz_[3 * r.begin()]), m, 3);
    index_->tree.knnSearch(mq, mi, md, kNeighbours + 1, flann::SearchParams(flann::FLANN_CHECKS_UNLIMITED));
    for (size_t i = 0; i < m; ++i)  // [0] is the sample itself (or a duplicate of it)
      out[r.begin() + i] = float(std::sqrt(double(dist[i * (kNeighbours + 1) + kNeighbours]) * M_PI / kNeighbours));
  });
  return out;
}

FarStats summarizeFar(const std::vector<double>& d, const std::vector<double>* local) {
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
  if (local && local->size() == d.size()) {
    size_t b = 0;
    for (size_t i = 0; i < d.size(); ++i) b += d[i] > 3 * (*local)[i];
    s.beyond3Local = double(b) / double(d.size());
  }
  return s;
}

}  // namespace sa
