#include "preprocess/cell_margin.h"

#include <algorithm>

#include "preprocess/grid_knn.h"
#include "preprocess/normals.h"

namespace sa {

struct MarginFinder::Index {
  GridKnn grid;
  Index(const double* pos, size_t n) : grid(pos, n, GridKnn::cellFor(estimateSpacing(pos, n).area, 24)) {}
};

MarginFinder::MarginFinder(const double* pos, const float* nrm, size_t n) : pos_(pos), nrm_(nrm) {
  if (n > 0) index_ = std::make_unique<Index>(pos, n);
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
  const size_t before = out.size();
  std::vector<std::pair<double, uint32_t>> near;
  for (size_t a = 0; a < q; ++a) {
    index_->grid.within(&queries[3 * a], radius, near, false);  // sorted and made unique below
    for (const auto& [d2, j] : near) {
      if (j >= c.first && j < c.first + c.count) continue;
      const Eigen::Vector3d d = Eigen::Vector3d(&pos_[3 * size_t(j)]) - c.origin;
      const double u = d.dot(c.u), v = d.dot(c.v);
      if (u < c.ext[0] - radius || u > c.ext[1] + radius || v < c.ext[2] - radius || v > c.ext[3] + radius) continue;
      const float* n = &nrm_[3 * size_t(j)];
      if (!(n[0] * c.w.x() + n[1] * c.w.y() + n[2] * c.w.z() > minCos)) continue;
      out.push_back(j);
    }
  }
  std::sort(out.begin() + long(before), out.end());
  out.erase(std::unique(out.begin() + long(before), out.end()), out.end());
}

void MarginFinder::normalField(const double* xyz, const float* hints, size_t m, double radius, float* out) const {
  std::copy(hints, hints + 3 * m, out);
  if (!index_ || m == 0) return;
  const double r2 = radius * radius;
  std::vector<std::pair<double, uint32_t>> near;
  for (size_t i = 0; i < m; ++i) {
    const Eigen::Vector3d hint(hints[3 * i], hints[3 * i + 1], hints[3 * i + 2]);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    index_->grid.within(&xyz[3 * i], radius, near);
    for (const auto& [d2, j] : near) {
      const float* n = &nrm_[3 * size_t(j)];
      const Eigen::Vector3d nn(n[0], n[1], n[2]);
      if (!(nn.dot(hint) > 0.5)) continue;
      const double q = 1 - d2 / r2;
      if (q > 0) sum += q * q * nn;
    }
    if (sum.norm() > 0) {
      sum.normalize();
      for (int a = 0; a < 3; ++a) out[3 * i + a] = float(sum[a]);
    }
  }
}

}  // namespace sa
