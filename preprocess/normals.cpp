#include "preprocess/normals.h"

#include "preprocess/grid_knn.h"

#include <flann/flann.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>

namespace sa {
namespace {

using KdTree = flann::Index<flann::L2_Simple<double>>;

Eigen::Vector3d towardOf(const NormalOrientation& orient, size_t i, const Eigen::Vector3d& p) {
  if (!orient.towardScanner.empty() && orient.scan) {
    const uint16_t s = *reinterpret_cast<const uint16_t*>(reinterpret_cast<const char*>(orient.scan) + i * orient.scanStride);
    return s < orient.towardScanner.size() ? orient.towardScanner[s] : Eigen::Vector3d::UnitZ();
  }
  if (orient.sheetSide.squaredNorm() > 0) return orient.sheetSide;
  return p - orient.center;
}

constexpr int kDensityNeighbours = 8;

// One point's neighbourhood: the moving-least-squares surface (Alexa et al. 2003; PCL's MLS
// with its "simple" projection): a Gaussian-weighted plane, then a weighted quadric height
// function over it; the point is projected onto the quadric along the plane normal.
struct LocalSurface {
  bool ok = false;
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // unoriented
  Eigen::Vector3d projected = Eigen::Vector3d::Zero();
  double residual = 0;  // weighted RMS distance of the neighbours to the quadric
  double radius = 0;    // distance to the farthest neighbour
};

LocalSurface fitLocal(const double* pos, const Eigen::Vector3d& p, const int* ind, const double* dist2, int k) {
  LocalSurface ls;
  double h2 = 0;
  for (int j = 0; j < k; ++j)
    if (ind[j] >= 0) h2 = std::max(h2, dist2[j]);
  if (!(h2 > 0)) return ls;
  ls.radius = std::sqrt(h2);
  // Weights exp(-d^2 / h^2) with h the neighbourhood radius (PCL's default Gaussian).
  double wsum = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  std::array<double, 64> wt{};
  const int kk = std::min(k, 64);
  int cnt = 0;
  for (int j = 0; j < kk; ++j) {
    if (ind[j] < 0) continue;
    wt[size_t(j)] = std::exp(-dist2[j] / h2);
    wsum += wt[size_t(j)];
    mean += wt[size_t(j)] * (Eigen::Vector3d(&pos[3 * size_t(ind[j])]) - p);
    ++cnt;
  }
  if (cnt < 3) return ls;
  mean /= wsum;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (int j = 0; j < kk; ++j) {
    if (ind[j] < 0) continue;
    const Eigen::Vector3d d = Eigen::Vector3d(&pos[3 * size_t(ind[j])]) - p - mean;
    cov += wt[size_t(j)] * d * d.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  const Eigen::Vector3d l = es.eigenvalues();
  if (es.info() != Eigen::Success || !(l[1] > 1e-12 * l[2]) || !(l[2] > 0)) return ls;  // collinear / duplicates
  const Eigen::Vector3d n = es.eigenvectors().col(0).normalized();
  const Eigen::Vector3d u = es.eigenvectors().col(2).normalized(), v = n.cross(u);
  ls.ok = true;
  ls.normal = n;
  ls.projected = p;
  if (cnt < 6) return ls;
  // Quadric z = c0 + c1 x + c2 y + c3 x^2 + c4 xy + c5 y^2 in (u, v, n) about the weighted
  // centroid, coordinates scaled by h (conditioning).
  const double h = ls.radius;
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
  for (int j = 0; j < kk; ++j) {
    if (ind[j] < 0) continue;
    const Eigen::Vector3d d = Eigen::Vector3d(&pos[3 * size_t(ind[j])]) - p - mean;
    const double x = d.dot(u) / h, y = d.dot(v) / h, z = d.dot(n) / h;
    Eigen::Matrix<double, 6, 1> f;
    f << 1, x, y, x * x, x * y, y * y;
    A.selfadjointView<Eigen::Lower>().rankUpdate(f, wt[size_t(j)]);
    b += wt[size_t(j)] * z * f;
  }
  A = A.selfadjointView<Eigen::Lower>();
  A.diagonal().array() += 1e-9 * A.trace();
  Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(A);
  const Eigen::Matrix<double, 6, 1> c = ldlt.solve(b);
  if (ldlt.info() != Eigen::Success || !c.allFinite()) return ls;
  double se = 0;
  for (int j = 0; j < kk; ++j) {
    if (ind[j] < 0) continue;
    const Eigen::Vector3d d = Eigen::Vector3d(&pos[3 * size_t(ind[j])]) - p - mean;
    const double x = d.dot(u) / h, y = d.dot(v) / h, z = d.dot(n) / h;
    const double r = z - (c[0] + c[1] * x + c[2] * y + c[3] * x * x + c[4] * x * y + c[5] * y * y);
    se += wt[size_t(j)] * r * r;
  }
  ls.residual = std::sqrt(se / wsum) * h;
  const Eigen::Vector3d d = -mean;  // the point itself relative to the centroid
  const double x = d.dot(u) / h, y = d.dot(v) / h;
  const double z = c[0] + c[1] * x + c[2] * y + c[3] * x * x + c[4] * x * y + c[5] * y * y;
  ls.projected = p + mean + (x * u + y * v + z * n) * h;
  const double fx = c[1] + 2 * c[3] * x + c[4] * y, fy = c[2] + c[4] * x + 2 * c[5] * y;
  ls.normal = (n - fx * u - fy * v).normalized();
  return ls;
}

// Estimated normals whose sign the orientation cue barely decides (|n . toward| < kWeakCue:
// walls under an airborne sensor's +z, grazing samples of a range scan, concave parts of a cloud
// oriented away from its centre) take the sign their oriented neighbours agree on instead,
// spreading breadth-first from the well-decided ones over the k-nearest-neighbour graph (Hoppe
// et al. 1992's propagation, limited to the undecided points). A wall thus inherits "outward"
// from the roof edge and the ground at its foot through their smoothly turning normals.
constexpr double kWeakCue = 0.25;

size_t propagateOrientation(const GridKnn& grid, const double* src, size_t n, int k, const NormalOrientation& orient,
                            const std::vector<uint8_t>& keep, float* nrm) {
  std::vector<int32_t> slot(n, -1);  // index into weak, or -1
  std::vector<uint32_t> weak;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f nn(&nrm[3 * i]);
    if (!keep[i] || nn.squaredNorm() == 0) continue;
    const Eigen::Vector3d t = towardOf(orient, i, Eigen::Vector3d(&src[3 * i]));
    const double tl = t.norm();
    if (tl > 0 && std::abs(nn.cast<double>().dot(t)) >= kWeakCue * tl) continue;
    slot[i] = int32_t(weak.size());
    weak.push_back(uint32_t(i));
  }
  if (weak.empty()) return 0;
  std::vector<int> lists(weak.size() * size_t(k), -1);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, weak.size(), 1024), [&](const tbb::blocked_range<size_t>& r) {
    std::vector<int> ind;
    std::vector<double> d2;
    for (size_t a = r.begin(); a != r.end(); ++a) {
      grid.query(weak[a], k, ind, d2);
      std::copy(ind.begin(), ind.end(), lists.begin() + long(a * size_t(k)));
    }
  });
  // 0: undecided; 1: decided (by the cue or by neighbours).
  std::vector<uint8_t> decided(weak.size(), 0);
  auto vote = [&](size_t a) {
    const uint32_t i = weak[a];
    const Eigen::Vector3f ni(&nrm[3 * size_t(i)]);
    double sum = 0;
    for (int j = 0; j < k; ++j) {
      const int q = lists[a * size_t(k) + size_t(j)];
      if (q < 0 || uint32_t(q) == i || !keep[size_t(q)]) continue;
      if (slot[size_t(q)] >= 0 && !decided[size_t(slot[size_t(q)])]) continue;
      sum += ni.dot(Eigen::Vector3f(&nrm[3 * size_t(q)]));
    }
    return sum;
  };
  size_t flipped = 0;
  std::vector<size_t> queue;
  auto decide = [&](size_t a, double v) {
    if (v < 0) {
      for (int c = 0; c < 3; ++c) nrm[3 * size_t(weak[a]) + c] = -nrm[3 * size_t(weak[a]) + c];
      ++flipped;
    }
    decided[a] = 1;
    queue.push_back(a);
  };
  // Seeds: undecided points next to decided ones (votes read only the cue-decided, so the seeds
  // do not depend on their order).
  std::vector<double> seedVote(weak.size(), 0);
  for (size_t a = 0; a < weak.size(); ++a) seedVote[a] = vote(a);
  for (size_t a = 0; a < weak.size(); ++a)
    if (seedVote[a] != 0) decide(a, seedVote[a]);
  for (size_t head = 0; head < queue.size(); ++head) {
    const size_t a = queue[head];
    for (int j = 0; j < k; ++j) {
      const int q = lists[a * size_t(k) + size_t(j)];
      if (q < 0 || slot[size_t(q)] < 0 || decided[size_t(slot[size_t(q)])]) continue;
      const size_t b = size_t(slot[size_t(q)]);
      const double v = vote(b);
      if (v != 0) decide(b, v);
    }
  }
  return flipped;
}

}  // namespace

size_t fitSurface(double* pos, size_t n, const NormalOrientation& orient, const SurfaceOptions& opt, float* nrm,
                  std::vector<uint8_t>& keep, float* localSpacing) {
  keep.assign(n, 1);
  if (n == 0) return 0;
  const int k = static_cast<int>(std::min<size_t>(std::max(opt.neighbours, 3), n));
  // The grid indexes a copy: smoothed positions are written back only when every point is done.
  std::vector<double> src(pos, pos + 3 * n);
  const Spacing sp = estimateSpacing(src.data(), n);
  const GridKnn grid(src.data(), n, GridKnn::cellFor(sp.area > 0 ? sp.area : sp.nearest, k));
  // Progress: 2n units, the density pass n of them (when there is one).
  std::atomic<size_t> units{0};
  auto tick = [&](size_t u) {  // reports in steps of 4096 units
    if (!opt.progress) return;
    const size_t before = units.fetch_add(u, std::memory_order_relaxed), steps = ((before + u) >> 12) - (before >> 12);
    if (steps) opt.progress(steps << 12);
  };
  std::vector<float> density;
  if (opt.outlierRatio > 0) {  // per point: the mean distance to its kDensityNeighbours nearest (local density)
    density.assign(n, 0.f);
    grid.forEach(int(std::min<size_t>(kDensityNeighbours + 1, n)), [&](size_t i, const int*, const double* d2, int m) {
      tick(1);
      double sum = 0;
      for (int j = 1; j < m; ++j) sum += std::sqrt(d2[j]);  // [0] is the point itself
      density[i] = m > 1 ? float(sum / (m - 1)) : 0.f;
    });
  }
  const size_t perFit = density.empty() ? 2 : 1;
  grid.forEach(k, [&](size_t i, const int* in, const double* dist, int m) {
    tick(perFit);
    const Eigen::Vector3d p(&src[3 * i]);
    if (localSpacing) {
      const int j = std::min(m - 1, kDensityNeighbours);  // [0] is the point itself
      localSpacing[i] = float(std::sqrt(dist[j] * M_PI / std::max(j, 1)));
    }
    if (!density.empty()) {
      // Outlier: much farther from its neighbours than they are from theirs (a local test,
      // so sparse but real regions - water returns, a scan's fringe - stay).
      std::array<float, 256> around;
      size_t c = 0;
      for (int j = 1; j < m && c < around.size(); ++j) around[c++] = density[size_t(in[j])];
      if (c > 0) {
        std::nth_element(around.begin(), around.begin() + long(c / 2), around.begin() + long(c));
        if (density[i] > opt.outlierRatio * around[c / 2]) {
          keep[i] = 0;
          return;
        }
      }
    }
    const LocalSurface ls = fitLocal(src.data(), p, in, dist, m);
    float* out = &nrm[3 * i];
    const Eigen::Vector3d given(out[0], out[1], out[2]);
    if (!ls.ok) {
      if (opt.estimateNormals) out[0] = out[1] = out[2] = 0.f;  // unknown
      return;
    }
    // Smooth only where the neighbourhood is a surface and the move is small against it
    // (layers, vegetation and sharp features keep their points where they are).
    const double move = (ls.projected - p).norm();
    if (opt.smooth && ls.residual < 0.25 * ls.radius && move < 0.5 * ls.radius)
      for (int c = 0; c < 3; ++c) pos[3 * i + c] = ls.projected[c];
    Eigen::Vector3d nn = ls.normal;
    const Eigen::Vector3d toward = given.squaredNorm() > 0.25 && !opt.estimateNormals ? given : towardOf(orient, i, p);
    if (nn.dot(toward) < 0) nn = -nn;
    if (opt.estimateNormals || opt.smooth)
      for (int c = 0; c < 3; ++c) out[c] = float(nn[c]);
  });
  if (opt.estimateNormals) propagateOrientation(grid, src.data(), n, k, orient, keep, nrm);
  return size_t(std::count(keep.begin(), keep.end(), 0));
}

void estimateNormals(const double* pos, size_t n, int k, const NormalOrientation& orient, float* nrm) {
  SurfaceOptions opt;
  opt.neighbours = k;
  opt.estimateNormals = true;
  opt.smooth = false;
  opt.outlierRatio = 0;
  std::vector<double> copy(pos, pos + 3 * n);
  std::vector<uint8_t> keep;
  fitSurface(copy.data(), n, orient, opt, nrm, keep);
}

namespace {

constexpr int kAreaNeighbours = 8;

// Nearest-neighbour distances of up to `queries` points of `tp[0..m)` whose index passes
// `accept`, appended to `out`, and their area spacings (r_8 sqrt(pi / 8), r_8 the distance to
// the 8th neighbour: the side of the area per point) to `area`.
template <class Accept>
void nearestDistances(const double* tp, size_t m, size_t queries, Accept accept, std::vector<double>& out,
                      std::vector<double>& area) {
  if (m < 2) return;
  flann::Matrix<double> data(const_cast<double*>(tp), m, 3);
  KdTree tree(data, flann::KDTreeSingleIndexParams(15));
  tree.buildIndex();
  std::vector<double> qs;
  for (size_t a = 0; a < m && qs.size() < 3 * queries; a += std::max<size_t>(1, m / queries))
    if (accept(a)) qs.insert(qs.end(), tp + 3 * a, tp + 3 * a + 3);
  const size_t q = qs.size() / 3;
  if (q == 0) return;
  const size_t k = std::min<size_t>(kAreaNeighbours + 1, m);
  std::vector<int> ind(q * k);
  std::vector<double> dist(q * k);
  flann::Matrix<int> mi(ind.data(), q, k);
  flann::Matrix<double> md(dist.data(), q, k);
  flann::Matrix<double> mq(qs.data(), q, 3);
  tree.knnSearch(mq, mi, md, int(k), flann::SearchParams(flann::FLANN_CHECKS_UNLIMITED));
  for (size_t a = 0; a < q; ++a) {
    if (dist[k * a + 1] > 0) out.push_back(std::sqrt(dist[k * a + 1]));  // [0] is the point itself
    if (k == kAreaNeighbours + 1 && dist[k * a + k - 1] > 0)
      area.push_back(std::sqrt(dist[k * a + k - 1] * M_PI / kAreaNeighbours));
  }
}

}  // namespace

Spacing estimateSpacing(const double* pos, size_t n, size_t samples) {
  if (n < 2) return {};
  std::vector<double> d, area;
  constexpr size_t kMaxTree = 1 << 17;
  if (n <= kMaxTree) {
    nearestDistances(pos, n, samples, [](size_t) { return true; }, d, area);
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
      }, d, area);
    }
  }
  auto median = [](std::vector<double>& v) {
    if (v.empty()) return 0.0;
    std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  Spacing s;
  s.nearest = median(d);
  s.area = median(area);
  return s;
}

}  // namespace sa
