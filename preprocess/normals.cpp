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

namespace {

// Nearest-neighbour distances of up to `queries` points of `tp[0..m)` whose index passes
// `accept`, appended to `out`.
template <class Accept>
void nearestDistances(const double* tp, size_t m, size_t queries, Accept accept, std::vector<double>& out) {
  if (m < 2) return;
  flann::Matrix<double> data(const_cast<double*>(tp), m, 3);
  KdTree tree(data, flann::KDTreeSingleIndexParams(15));
  tree.buildIndex();
  std::vector<double> qs;
  for (size_t a = 0; a < m && qs.size() < 3 * queries; a += std::max<size_t>(1, m / queries))
    if (accept(a)) qs.insert(qs.end(), tp + 3 * a, tp + 3 * a + 3);
  const size_t q = qs.size() / 3;
  if (q == 0) return;
  std::vector<int> ind(q * 2);
  std::vector<double> dist(q * 2);
  flann::Matrix<int> mi(ind.data(), q, 2);
  flann::Matrix<double> md(dist.data(), q, 2);
  flann::Matrix<double> mq(qs.data(), q, 3);
  tree.knnSearch(mq, mi, md, 2, flann::SearchParams(flann::FLANN_CHECKS_UNLIMITED));
  for (size_t a = 0; a < q; ++a)
    if (dist[2 * a + 1] > 0) out.push_back(std::sqrt(dist[2 * a + 1]));  // [0] is the point itself
}

}  // namespace

double estimateSpacing(const double* pos, size_t n, size_t samples) {
  if (n < 2) return 0;
  std::vector<double> d;
  constexpr size_t kMaxTree = 1 << 17;
  if (n <= kMaxTree) {
    nearestDistances(pos, n, samples, [](size_t) { return true; }, d);
  } else {
    // A kd-tree over millions of points costs more than the rest of the chunk's octree.
    // Spacing is local: take a few sub-cubes holding about kMaxTree / 4 points each (at full
    // density, so regular scan grids keep their true spacing), and query only points away
    // from the sub-cube's faces.
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
    for (size_t i = 0; i < n; ++i) {
      lo = lo.cwiseMin(Eigen::Vector3d(&pos[3 * i]));
      hi = hi.cwiseMax(Eigen::Vector3d(&pos[3 * i]));
    }
    const size_t want = kMaxTree / 4;
    double side = (hi - lo).maxCoeff() * std::sqrt(double(want) / double(n));  // surfaces: area ~ side^2
    std::vector<double> sub;
    for (int seed = 0; seed < 4; ++seed) {
      const Eigen::Vector3d c(&pos[3 * ((2 * seed + 1) * n / 8)]);
      for (int attempt = 0; attempt < 8; ++attempt) {
        sub.clear();
        for (size_t i = 0; i < n && sub.size() <= 3 * 4 * want; ++i) {
          const Eigen::Vector3d p(&pos[3 * i]);
          if (((p - c).cwiseAbs().array() <= side / 2).all()) sub.insert(sub.end(), {p.x(), p.y(), p.z()});
        }
        const size_t m = sub.size() / 3;
        if (m < want / 4) side *= 1.6;
        else if (m > 4 * want) side /= 1.6;
        else break;
      }
      const double inner = side / 4;
      nearestDistances(sub.data(), sub.size() / 3, samples / 4, [&](size_t a) {
        return ((Eigen::Vector3d(&sub[3 * a]) - c).cwiseAbs().array() <= inner).all();
      }, d);
    }
  }
  if (d.empty()) return 0;
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return d[d.size() / 2];
}

}  // namespace sa
