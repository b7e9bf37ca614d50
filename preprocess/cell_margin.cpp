#include "preprocess/cell_margin.h"

#include <flann/flann.hpp>

#include <algorithm>

namespace sa {

struct MarginFinder::Index {
  flann::Index<flann::L2_Simple<double>> tree;
  explicit Index(flann::Matrix<double> data) : tree(data, flann::KDTreeSingleIndexParams(15)) { tree.buildIndex(); }
};

MarginFinder::MarginFinder(const double* pos, const float* nrm, size_t n) : pos_(pos), nrm_(nrm) {
  if (n > 0) index_ = std::make_unique<Index>(flann::Matrix<double>(const_cast<double*>(pos), n, 3));
}

MarginFinder::~MarginFinder() = default;

void MarginFinder::find(const Cell& c, double radius, double minCos, std::vector<uint32_t>& out) const {
  if (!index_ || c.count == 0) return;
  // Only the cell's points near the border of its extent can have neighbours in the margin.
  std::vector<double> queries;
  for (uint32_t i = c.first; i < c.first + c.count; ++i) {
    const Eigen::Vector3d d = Eigen::Vector3d(&pos_[3 * size_t(i)]) - c.origin;
    const double u = d.dot(c.u), v = d.dot(c.v);
    if (u < c.ext[0] + radius || u > c.ext[1] - radius || v < c.ext[2] + radius || v > c.ext[3] - radius)
      queries.insert(queries.end(), &pos_[3 * size_t(i)], &pos_[3 * size_t(i)] + 3);
  }
  if (queries.empty()) return;
  const size_t q = queries.size() / 3;
  std::vector<std::vector<int>> ind;
  std::vector<std::vector<double>> dist;
  flann::Matrix<double> mq(queries.data(), q, 3);
  index_->tree.radiusSearch(mq, ind, dist, float(radius * radius), flann::SearchParams(flann::FLANN_CHECKS_UNLIMITED));
  const size_t before = out.size();
  for (const auto& list : ind)
    for (int j : list) {
      if (j < 0 || (uint32_t(j) >= c.first && uint32_t(j) < c.first + c.count)) continue;
      const Eigen::Vector3d d = Eigen::Vector3d(&pos_[3 * size_t(j)]) - c.origin;
      const double u = d.dot(c.u), v = d.dot(c.v);
      if (u < c.ext[0] - radius || u > c.ext[1] + radius || v < c.ext[2] - radius || v > c.ext[3] + radius) continue;
      const float* n = &nrm_[3 * size_t(j)];
      if (!(n[0] * c.w.x() + n[1] * c.w.y() + n[2] * c.w.z() > minCos)) continue;
      out.push_back(uint32_t(j));
    }
  std::sort(out.begin() + long(before), out.end());
  out.erase(std::unique(out.begin() + long(before), out.end()), out.end());
}

void MarginFinder::normalField(const double* xyz, const float* hints, size_t m, double radius, float* out) const {
  std::copy(hints, hints + 3 * m, out);
  if (!index_ || m == 0) return;
  std::vector<std::vector<int>> ind;
  std::vector<std::vector<double>> dist;
  flann::Matrix<double> mq(const_cast<double*>(xyz), m, 3);
  index_->tree.radiusSearch(mq, ind, dist, float(radius * radius), flann::SearchParams(flann::FLANN_CHECKS_UNLIMITED));
  const double r2 = radius * radius;
  for (size_t i = 0; i < m; ++i) {
    const Eigen::Vector3d hint(hints[3 * i], hints[3 * i + 1], hints[3 * i + 2]);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (size_t k = 0; k < ind[i].size(); ++k) {
      const float* n = &nrm_[3 * size_t(ind[i][k])];
      const Eigen::Vector3d nn(n[0], n[1], n[2]);
      if (!(nn.dot(hint) > 0.5)) continue;
      const double q = 1 - dist[i][k] / r2;
      if (q > 0) sum += q * q * nn;
    }
    if (sum.norm() > 0) {
      sum.normalize();
      for (int a = 0; a < 3; ++a) out[3 * i + a] = float(sum[a]);
    }
  }
}

}  // namespace sa
