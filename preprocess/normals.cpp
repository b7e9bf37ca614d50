#include "preprocess/normals.h"

#include <flann/flann.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

namespace sa {
namespace {

using KdTree = flann::Index<flann::L2_Simple<double>>;

}  // namespace

void estimateNormals(const double* pos, size_t n, int k, const NormalOrientation& orient, float* nrm) {
  if (n == 0) return;
  k = static_cast<int>(std::min<size_t>(k, n));
  flann::Matrix<double> data(const_cast<double*>(pos), n, 3);
  KdTree tree(data, flann::KDTreeSingleIndexParams(15));
  tree.buildIndex();
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& r) {
    const size_t m = r.size();
    std::vector<int> ind(m * k);
    std::vector<double> dist(m * k);
    flann::Matrix<int> mi(ind.data(), m, k);
    flann::Matrix<double> md(dist.data(), m, k);
    flann::Matrix<double> q(const_cast<double*>(pos + 3 * r.begin()), m, 3);
    flann::SearchParams sp(flann::FLANN_CHECKS_UNLIMITED);
    tree.knnSearch(q, mi, md, k, sp);
    for (size_t a = 0; a < m; ++a) {
      const size_t i = r.begin() + a;
      const Eigen::Vector3d p(&pos[3 * i]);
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      int cnt = 0;
      for (int j = 0; j < k; ++j) {
        const int id = ind[a * k + j];
        if (id < 0) continue;
        mean += Eigen::Vector3d(&pos[3 * size_t(id)]) - p;
        ++cnt;
      }
      float* out = &nrm[3 * i];
      out[0] = out[1] = out[2] = 0.f;
      if (cnt < 3) continue;
      mean /= cnt;
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (int j = 0; j < k; ++j) {
        const int id = ind[a * k + j];
        if (id < 0) continue;
        Eigen::Vector3d d = Eigen::Vector3d(&pos[3 * size_t(id)]) - p - mean;
        cov += d * d.transpose();
      }
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
      const Eigen::Vector3d l = es.eigenvalues();
      if (es.info() != Eigen::Success || !(l[1] > 1e-12 * l[2]) || !(l[2] > 0)) continue;  // collinear / duplicates
      Eigen::Vector3d nn = es.eigenvectors().col(0).normalized();
      Eigen::Vector3d toward;
      if (!orient.towardScanner.empty() && orient.scan) {
        const uint16_t s = *reinterpret_cast<const uint16_t*>(reinterpret_cast<const char*>(orient.scan) + i * orient.scanStride);
        toward = s < orient.towardScanner.size() ? orient.towardScanner[s] : Eigen::Vector3d::UnitZ();
      } else {
        toward = p - orient.center;
      }
      if (nn.dot(toward) < 0) nn = -nn;
      out[0] = float(nn.x()); out[1] = float(nn.y()); out[2] = float(nn.z());
    }
  });
}

double estimateSpacing(const double* pos, size_t n, size_t samples) {
  if (n < 2) return 0;
  flann::Matrix<double> data(const_cast<double*>(pos), n, 3);
  KdTree tree(data, flann::KDTreeSingleIndexParams(15));
  tree.buildIndex();
  const size_t m = std::min(samples, n);
  std::vector<double> q(3 * m);
  for (size_t a = 0; a < m; ++a) {
    const size_t i = a * n / m;
    std::copy(pos + 3 * i, pos + 3 * i + 3, &q[3 * a]);
  }
  std::vector<int> ind(m * 2);
  std::vector<double> dist(m * 2);
  flann::Matrix<int> mi(ind.data(), m, 2);
  flann::Matrix<double> md(dist.data(), m, 2);
  flann::Matrix<double> mq(q.data(), m, 3);
  tree.knnSearch(mq, mi, md, 2, flann::SearchParams(flann::FLANN_CHECKS_UNLIMITED));
  std::vector<double> d;
  d.reserve(m);
  for (size_t a = 0; a < m; ++a) {
    // The nearest hit is the point itself (distance 0), unless a duplicate came first.
    const double d1 = dist[2 * a + 1];
    if (d1 > 0) d.push_back(std::sqrt(d1));
  }
  if (d.empty()) return 0;
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return d[d.size() / 2];
}

}  // namespace sa
