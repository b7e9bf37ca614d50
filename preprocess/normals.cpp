#include "preprocess/normals.h"

#include "preprocess/fit_math.h"
#include "preprocess/grid_knn.h"

#include <flann/flann.hpp>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

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
  // The point lies at the edge of its neighbourhood (a chunk's face, a scan's border): the
  // neighbours' weighted centroid is off it by over kEdgeOffset of the radius in the plane.
  bool edge = false;
};

// A half-disk's centroid lies 4 / (3 pi) = 0.42 of the radius off its centre; a full one's, with
// 24 random neighbours, about 0.1.
constexpr double kEdgeOffset = 0.25;

LocalSurface fitLocal(const double* pos, const Eigen::Vector3d& p, const int* ind, const double* dist2, int k) {
  LocalSurface ls;
  // The neighbours relative to p, gathered once (each pass below reads them again).
  std::array<Eigen::Vector3d, 64> d;
  std::array<double, 64> wt;
  const int kk = std::min(k, 64);
  int cnt = 0;
  double h2 = 0;
  for (int j = 0; j < kk; ++j) {
    if (ind[j] < 0) continue;
    d[size_t(cnt)] = Eigen::Vector3d(&pos[3 * size_t(ind[j])]) - p;
    wt[size_t(cnt)] = dist2[j];
    h2 = std::max(h2, dist2[j]);
    ++cnt;
  }
  for (int j = kk; j < k; ++j)
    if (ind[j] >= 0) h2 = std::max(h2, dist2[j]);
  if (!(h2 > 0)) return ls;
  ls.radius = std::sqrt(h2);
  if (cnt < 3) return ls;
  // Weights exp(-d^2 / h^2) with h the neighbourhood radius (PCL's default Gaussian), by
  // gaussianWeight in a loop of its own, which the compiler codes two weights to an instruction.
  for (int j = 0; j < cnt; ++j) wt[size_t(j)] = gaussianWeight(wt[size_t(j)] / h2);
  double wsum = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (int j = 0; j < cnt; ++j) {
    wsum += wt[size_t(j)];
    mean += wt[size_t(j)] * d[size_t(j)];
  }
  mean /= wsum;
  for (int j = 0; j < cnt; ++j) d[size_t(j)] -= mean;  // from here on relative to the weighted centroid
  // The covariance's lower triangle (what computeDirect reads), each entry summed in scalars as
  // Eigen's outer product summed it, (w d_r) d_c: Eigen's 3x3 sum went through the stack and
  // stalled on its own stores (a third of the fit's time).
  double c00 = 0, c10 = 0, c11 = 0, c20 = 0, c21 = 0, c22 = 0;
  for (int j = 0; j < cnt; ++j) {
    const double w = wt[size_t(j)], x = d[size_t(j)].x(), y = d[size_t(j)].y(), z = d[size_t(j)].z();
    const double wx = w * x, wy = w * y, wz = w * z;
    c00 += wx * x, c10 += wy * x, c11 += wy * y, c20 += wz * x, c21 += wz * y, c22 += wz * z;
  }
  Eigen::Matrix3d cov;
  cov << c00, c10, c20, c10, c11, c21, c20, c21, c22;
  // Closed form (Eigen's computeDirect, like PCL's eigen33): the normal's eigenvalue is well apart
  // from the others on a surface, where the closed form is as good as the iterative solver at a
  // fraction of its cost.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
  es.computeDirect(cov);
  const Eigen::Vector3d l = es.eigenvalues();
  if (es.info() != Eigen::Success || !(l[1] > 1e-12 * l[2]) || !(l[2] > 0)) return ls;  // collinear / duplicates
  const Eigen::Vector3d n = es.eigenvectors().col(0).normalized();
  const Eigen::Vector3d u = es.eigenvectors().col(2).normalized(), v = n.cross(u);
  ls.ok = true;
  ls.edge = (mean - n * n.dot(mean)).norm() > kEdgeOffset * ls.radius;
  ls.normal = n;
  ls.projected = p;
  if (cnt < 6) return ls;
  // Quadric z = c0 + c1 x + c2 y + c3 x^2 + c4 xy + c5 y^2 in (u, v, n) about the weighted
  // centroid, coordinates scaled by h (conditioning).
  const double h = ls.radius;
  alignas(16) double xyz[3 * 64];  // (x, y, z) in that frame, per neighbour
  // A += w f f^T and b += w f z, the lower triangle only (what the solve reads), in pairs of
  // lanes (GCC's vector extension; SSE2 codes a pair to an instruction): row r of A holds
  // f[r] w f[0..r], in r / 2 + 1 pairs (the lane past an even row's last entry is summed and not
  // read). Each entry is the same sum of the same products as one scalar at a time, in the same
  // order. (Under cachegrind these sums took 84 instructions a neighbour in the square form the
  // compiler vectorized itself, about 74 in this one.)
  using V2 = double __attribute__((vector_size(16)));
  for (int j = 0; j < cnt; ++j) {
    const Eigen::Vector3d& dj = d[size_t(j)];
    xyz[3 * j] = dj.dot(u), xyz[3 * j + 1] = dj.dot(v), xyz[3 * j + 2] = dj.dot(n);
  }
  // The divisions by h in one loop over the coordinates, which the compiler codes two to an
  // instruction (three scalar divisions a neighbour were a seventh of the fit).
  for (int t = 0; t < 3 * cnt; ++t) xyz[t] /= h;
  V2 a[6][3] = {}, bb[3] = {};  // a[r][p]: entries (r, 2p) and (r, 2p + 1); bb[p]: b's 2p, 2p + 1
  for (int j = 0; j < cnt; ++j) {
    const double x = xyz[3 * j], y = xyz[3 * j + 1], z = xyz[3 * j + 2], w = wt[size_t(j)];
    const V2 f[3] = {V2{1, x}, V2{y, x * x}, V2{x * y, y * y}};
    const V2 wv = {w, w}, zv = {z, z};
    const V2 wf[3] = {wv * f[0], wv * f[1], wv * f[2]};  // w f[0..5]
    for (int p = 0; p < 3; ++p) bb[p] += wf[p] * zv;
    for (int r = 0; r < 6; ++r) {
      const V2 wr = {wf[r / 2][r % 2], wf[r / 2][r % 2]};
      for (int p = 0; p <= r / 2; ++p) a[r][p] += wr * f[p];
    }
  }
  double A[6][6], b[6], c[6];  // A's lower triangle
  double trace = 0;
  for (int r = 0; r < 6; ++r) {
    b[r] = bb[r / 2][r % 2];
    for (int q = 0; q <= r; ++q) A[r][q] = a[r][q / 2][q % 2];
    trace += A[r][r];
  }
  for (int r = 0; r < 6; ++r) A[r][r] += 1e-9 * trace;
  if (!solveSpd6(A, b, c)) return ls;
  double se = 0;
  for (int j = 0; j < cnt; ++j) {
    const double x = xyz[3 * j], y = xyz[3 * j + 1], z = xyz[3 * j + 2];
    const double r = z - (c[0] + c[1] * x + c[2] * y + c[3] * x * x + c[4] * x * y + c[5] * y * y);
    se += wt[size_t(j)] * r * r;
  }
  ls.residual = std::sqrt(se / wsum) * h;
  const Eigen::Vector3d dp = -mean;  // the point itself relative to the centroid
  const double x = dp.dot(u) / h, y = dp.dot(v) / h;
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
// 0.5 (60 degrees off the cue): at 0.25 the tilted normals a chunk's face leaves on a wall it cut
// off from its foot (one-sided neighbourhoods lean by 15-30 degrees) still decided, and seeded
// the whole wall with the wrong sign (docs/BENCHMARKS.md, "Chunk faces and estimated normals").
constexpr double kWeakCue = 0.5;

// Whether the cue toward t barely decides the sign of normal n (a zero t decides nothing).
bool weakCue(const float* n, const Eigen::Vector3d& t) {
  const double tl = t.norm();
  return !(tl > 0 && std::abs(Eigen::Vector3f(n[0], n[1], n[2]).cast<double>().dot(t)) >= kWeakCue * tl);
}

// Neighbour lists kept from the fit's own k-nearest-neighbour pass for a later step (no second
// search): per point its index, then k neighbours (-1 pads). Those of the points the cue left
// undecided (propagateOrientation) and of those whose neighbours reach past their grid block
// (markOutliers).
struct NeighbourLists {
  int k = 0;
  size_t cap = SIZE_MAX;  // at most this many records; add() refuses more
  std::atomic<size_t> count{0};
  // Per thread, blocks of records filled in turn (no vector doubling: at millions of wall
  // points a doubling vector would briefly hold three times the lists).
  static constexpr size_t kBlockInts = 1 << 16;
  tbb::enumerable_thread_specific<std::vector<std::vector<int>>> perThread;
  bool add(size_t i, const int* ind, int m) {
    if (cap != SIZE_MAX && count.fetch_add(1, std::memory_order_relaxed) >= cap) return false;
    std::vector<std::vector<int>>& blocks = perThread.local();
    const size_t rec = size_t(k) + 1;
    if (blocks.empty() || blocks.back().size() + rec > blocks.back().capacity()) {
      blocks.emplace_back();
      blocks.back().reserve(std::max(kBlockInts, rec));
    }
    std::vector<int>& v = blocks.back();
    v.push_back(int(i));
    v.insert(v.end(), ind, ind + m);
    v.insert(v.end(), size_t(k - m), -1);
    return true;
  }
  // Every record as (point, its list), ordered by point (threads append in any order; a point
  // has one record, so the order is the same on any number of cores).
  std::vector<std::pair<uint32_t, const int*>> sorted() const {
    std::vector<std::pair<uint32_t, const int*>> recs;
    for (const std::vector<std::vector<int>>& blocks : perThread)
      for (const std::vector<int>& v : blocks)
        for (size_t r = 0; r < v.size(); r += size_t(k) + 1) recs.emplace_back(uint32_t(v[r]), &v[r + 1]);
    tbb::parallel_sort(recs.begin(), recs.end());
    return recs;
  }
};

// A chunk's points in the grid's order over the caller's arrays: point i of the order is
// orig[i] there (the normals and flags are not copied: at millions of points that is memory).
struct OrderedPoints {
  const double* src;  // positions, in the grid's order
  const uint32_t* orig;
  const uint32_t* callerIndex;  // point i of the order was callerIndex[i] in the caller's order
  size_t neighboursFrom;        // SurfaceOptions::neighboursFrom
  float* nrm;     // the caller's normals
  uint8_t* keep;  // the caller's flags
  size_t at(size_t i) const { return orig ? orig[i] : i; }  // no orig: the caller's arrays are in the grid's order
  float* normal(size_t i) const { return nrm + 3 * at(i); }
  bool kept(size_t i) const { return keep[at(i)] != 0; }
};

size_t propagateOrientation(const NeighbourLists& weakLists, size_t n, const OrderedPoints& pts) {
  const int k = weakLists.k;
  std::vector<std::pair<uint32_t, const int*>> weak = weakLists.sorted();
  // Outliers found after the fit added them: never read, never decided.
  weak.erase(std::remove_if(weak.begin(), weak.end(), [&](const auto& w) { return !pts.kept(w.first); }), weak.end());
  if (weak.empty()) return 0;
  std::vector<int32_t> slot(n, -1);  // index into weak, or -1
  for (size_t a = 0; a < weak.size(); ++a) slot[weak[a].first] = int32_t(a);
  // 0: undecided; 1: decided (by the cue or by neighbours).
  std::vector<uint8_t> decided(weak.size(), 0);
  auto vote = [&](size_t a) {
    const uint32_t i = weak[a].first;
    const Eigen::Vector3f ni(pts.normal(i));
    double sum = 0;
    for (int j = 0; j < k; ++j) {
      const int q = weak[a].second[j];
      if (q < 0 || uint32_t(q) == i || !pts.kept(size_t(q))) continue;
      if (slot[size_t(q)] >= 0 && !decided[size_t(slot[size_t(q)])]) continue;
      sum += ni.dot(Eigen::Vector3f(pts.normal(size_t(q))));
    }
    return sum;
  };
  size_t flipped = 0;
  std::vector<size_t> queue;
  auto decide = [&](size_t a, double v) {
    if (v < 0) {
      float* nn = pts.normal(weak[a].first);
      for (int c = 0; c < 3; ++c) nn[c] = -nn[c];
      ++flipped;
    }
    decided[a] = 1;
    queue.push_back(a);
  };
  // Seeds: undecided points next to decided ones (votes read only the cue-decided, so the seeds
  // do not depend on their order).
  std::vector<double> seedVote(weak.size(), 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, weak.size(), 1 << 10), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t a = r.begin(); a != r.end(); ++a) seedVote[a] = vote(a);
  });
  for (size_t a = 0; a < weak.size(); ++a)
    if (seedVote[a] != 0) decide(a, seedVote[a]);
  for (size_t head = 0; head < queue.size(); ++head) {
    const size_t a = queue[head];
    for (int j = 0; j < k; ++j) {
      const int q = weak[a].second[j];
      if (q < 0 || slot[size_t(q)] < 0 || decided[size_t(slot[size_t(q)])]) continue;
      const size_t b = size_t(slot[size_t(q)]);
      const double v = vote(b);
      if (v != 0) decide(b, v);
    }
  }
  return flipped;
}

// Where a point's k nearest lie for the outlier test (markOutliers).
enum NeighbourPlace : uint8_t {
  kInBlock,  // within its 3x3x3 block of grid cells
  kListed,   // beyond, and its list was kept
  kBeyond,   // beyond, and the lists' cap was reached: asked for again
};

// The lists kept for the outlier test: a third of the points at most (about 32 bytes a point of
// the chunk). Points whose neighbours reach past their block: 0.16 % of the 2 M-point survey,
// 15 % of lone-star, 35 % of the mug's stereo cloud (a third listed, the rest ask again).
constexpr size_t kListedShare = 3;

// Outlier: much farther from its neighbours than they are from theirs (a local test, so sparse
// but real regions - water returns, a scan's fringe - stay): its density (mean distance to its
// kDensityNeighbours nearest) over ratio times the median of its k nearest neighbours'. Where
// those lie within the point's 3x3x3 block of grid cells (place kInBlock), the same rank over
// the whole block bounds the median from below and most points pass on that alone; the few
// that do not ask for their k nearest again, from their block only. The others were listed
// during the fit.
void markOutliers(const GridKnn& grid, const std::vector<float>& density, const std::vector<uint8_t>& place,
                  const NeighbourLists& listed, int k, double ratio, const OrderedPoints& pts) {
  const size_t n = density.size();
  // A point's median is the (c / 2)-th smallest of its c = k - 1 neighbours' densities (the list
  // less its first entry), no less than the same rank over its whole block.
  const size_t c = std::min(size_t(k), n) - 1;
  const RawVector<float> low = grid.blockRank(density.data(), c / 2);
  auto test = [&](size_t i, const int* ind, size_t m, std::vector<float>& around) {
    around.clear();
    for (size_t j = 1; j < m; ++j)
      if (ind[j] >= 0) around.push_back(density[size_t(ind[j])]);
    if (around.empty()) return;
    std::nth_element(around.begin(), around.begin() + long(around.size() / 2), around.end());
    if (density[i] > ratio * around[around.size() / 2]) pts.keep[pts.at(i)] = 0;
  };
  const std::vector<std::pair<uint32_t, const int*>> recs = listed.sorted();
  tbb::parallel_for(tbb::blocked_range<size_t>(0, recs.size(), 1 << 10), [&](const tbb::blocked_range<size_t>& r) {
    std::vector<float> around;
    for (size_t a = r.begin(); a != r.end(); ++a) test(recs[a].first, recs[a].second, size_t(listed.k), around);
  });
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 12), [&](const tbb::blocked_range<size_t>& r) {
    std::vector<int> ind;
    std::vector<double> d2;
    std::vector<float> around;
    for (size_t i = r.begin(); i != r.end(); ++i) {
      if (place[i] == kListed || (place[i] == kInBlock && !(density[i] > ratio * low[i]))) continue;
      grid.query(i, k, ind, d2);
      test(i, ind.data(), ind.size(), around);
    }
  });
}

// The fit over points in the grid's order; pos and localSpacing are the caller's (by orig).
size_t fitOrdered(const GridKnn& grid, const OrderedPoints& pts, size_t n, int k, const NormalOrientation& orient,
                  const SurfaceOptions& opt, double* pos, float* localSpacing) {
  const double* src = pts.src;
  // Progress: 2n units, 2 a point fitted, reported in steps of 4096 units. Each thread counts its
  // own and reports each 4096 it reaches (one atomic add a point, shared by the cores, was 2 % of
  // a pack's CPU samples); a call's own id keeps a thread's count from carrying into the next
  // call. What no thread reached is reported at the end, as one step.
  static std::atomic<uint64_t> calls{0};
  const uint64_t call = ++calls;
  std::atomic<size_t> reported{0};
  auto tick = [&](size_t u) {
    if (!opt.progress) return;
    thread_local struct {
      uint64_t call = 0;
      size_t units = 0;
    } mine;
    if (mine.call != call) mine.call = call, mine.units = 0;
    if ((mine.units += u) < 4096) return;
    reported.fetch_add(4096, std::memory_order_relaxed);
    mine.units -= 4096;
    opt.progress(4096);
  };
  // One k-nearest-neighbour pass for both the fit and the density: a point's
  // kDensityNeighbours nearest are the first of its k (the order is exact, ties by index). A fit
  // never reads the outlier flags, so fitting a point that then turns out an outlier changes
  // nothing but that point, which is dropped. (The density's own pass was 23 % of the fit's
  // time on the 2 M-point survey.)
  const bool outliers = opt.outlierRatio > 0;
  // The quadric gives normals and smoothed positions: with the file's normals kept and the
  // points left where they are, the pass serves only the spacing and the outlier test.
  const bool fit = opt.estimateNormals || opt.smooth;
  const int kd = int(std::min<size_t>(kDensityNeighbours + 1, n));  // [0] is the point itself
  std::vector<float> density(outliers ? n : 0, 0.f);
  std::vector<uint8_t> place(outliers ? n : 0, kInBlock);
  NeighbourLists weak, listed;
  weak.k = listed.k = k;
  listed.cap = n / kListedShare;
  grid.forEach(outliers ? std::max(k, kd) : fit ? k : kd, [&](size_t i, const int* in, const double* dist, int mq) {
    tick(2);
    const Eigen::Vector3d p(&src[3 * i]);
    const size_t o = pts.at(i);
    if (localSpacing) {
      const int j = std::min(mq - 1, kDensityNeighbours);  // [0] is the point itself
      localSpacing[o] = float(std::sqrt(dist[j] * M_PI / std::max(j, 1)));
    }
    const int m = std::min(mq, k);
    if (outliers) {  // per point: the mean distance to its kDensityNeighbours nearest
      const int md = std::min(mq, kd);
      double sum = 0;
      for (int j = 1; j < md; ++j) sum += std::sqrt(dist[j]);
      density[i] = md > 1 ? float(sum / (md - 1)) : 0.f;
      const double g = grid.blockReach(i);
      if (!(std::isinf(g) || dist[m - 1] < g * g)) place[i] = listed.add(i, in, m) ? kListed : kBeyond;
    }
    if (!fit || pts.callerIndex[i] >= pts.neighboursFrom) return;
    const LocalSurface ls = fitLocal(src, p, in, dist, m);
    float* out = pts.normal(i);
    const Eigen::Vector3d given(out[0], out[1], out[2]);
    if (!ls.ok) {
      if (opt.estimateNormals) out[0] = out[1] = out[2] = 0.f;  // unknown
      return;
    }
    if (opt.surfaceLike && !ls.edge && ls.residual < kSurfaceResidual * ls.radius) opt.surfaceLike[o] = 1;
    // Smooth only where the neighbourhood is a surface and the move is small against it
    // (layers, vegetation and sharp features keep their points where they are).
    const double move = (ls.projected - p).norm();
    if (opt.smooth && ls.residual < 0.25 * ls.radius && move < 0.5 * ls.radius)
      for (int c = 0; c < 3; ++c) pos[3 * o + c] = ls.projected[c];
    Eigen::Vector3d nn = ls.normal;
    const Eigen::Vector3d toward = given.squaredNorm() > 0.25 && !opt.estimateNormals ? given : towardOf(orient, o, p);
    if (nn.dot(toward) < 0) nn = -nn;
    if (opt.estimateNormals || opt.smooth)
      for (int c = 0; c < 3; ++c) out[c] = float(nn[c]);
    // At an edge the fit leans (the quadric extrapolates past the last neighbours): a point
    // there would seed its wall with a sign its tilt decided, so its neighbours decide it. At a
    // chunk's bottom face a wall's tilted normals flipped whole faces (14 % of the wall points
    // of a building cut 10 m above its foot; 0 with the foot in the chunk).
    if (opt.estimateNormals && (ls.edge || weakCue(out, toward))) weak.add(i, in, m);
  });
  if (opt.progress && reported < 2 * n) opt.progress(2 * n - reported);
  if (outliers) markOutliers(grid, density, place, listed, k, opt.outlierRatio, pts);
  if (opt.estimateNormals) propagateOrientation(weak, n, pts);
  size_t removed = 0;
  for (size_t i = 0; i < n; ++i) {
    if (pts.callerIndex[i] < pts.neighboursFrom) removed += !pts.kept(i);
    else pts.keep[pts.at(i)] = 0;
  }
  return removed;
}

// v's records of `width` values laid out in `order` (the record now at i was at order[i]), in
// v's own memory (the caller's pointer).
template <class T>
void permuteInPlace(T* v, size_t width, const std::vector<uint32_t>& order) {
  const size_t n = order.size();
  RawVector<T> copy(width * n);  // copied on every core, like the permutation
  tbb::parallel_for(tbb::blocked_range<size_t>(0, width * n, 1 << 16), [&](const tbb::blocked_range<size_t>& r) {
    std::copy(v + r.begin(), v + r.end(), copy.begin() + long(r.begin()));
  });
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) std::copy_n(&copy[width * size_t(order[i])], width, &v[width * i]);
  });
}

}  // namespace

size_t fitSurface(double* pos, size_t n, const NormalOrientation& orient, const SurfaceOptions& opt, float* nrm,
                  std::vector<uint8_t>& keep, float* localSpacing, std::vector<uint32_t>* order) {
  keep.assign(n, 1);
  if (n == 0) return 0;
  const int k = static_cast<int>(std::min<size_t>(std::max(opt.neighbours, 3), n));
  double spacing = opt.spacing;
  if (!(spacing > 0)) {
    const Spacing sp = estimateSpacing(pos, n);
    spacing = sp.area > 0 ? sp.area : sp.nearest;
  }
  // Every pass visits the points in the grid's spatial order, reading a copy of the positions
  // in that order (smoothed positions go to pos, which no pass reads): in a file's order a
  // point's neighbours lie all over the chunk's arrays, and at millions of points the fit
  // mostly waited for memory.
  std::vector<uint32_t> orig;
  RawVector<double> src;
  const GridKnn grid = GridKnn(pos, n, GridKnn::cellFor(spacing, k)).inOrder(src, orig);
  NormalOrientation laidOrient;
  std::vector<uint16_t> scans;
  const bool laid = opt.layOut && order;
  if (laid) {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 15), [&](const tbb::blocked_range<size_t>& r) {
      std::copy(src.begin() + long(3 * r.begin()), src.begin() + long(3 * r.end()), pos + 3 * r.begin());
    });
    permuteInPlace(nrm, 3, orig);
    laidOrient = orient;
    if (orient.scan) {
      scans.resize(n);
      tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i)
          scans[i] = *reinterpret_cast<const uint16_t*>(reinterpret_cast<const char*>(orient.scan) + orig[i] * orient.scanStride);
      });
      laidOrient.scan = scans.data();
      laidOrient.scanStride = sizeof(uint16_t);
    }
  }
  const size_t removed = fitOrdered(grid, {src.data(), laid ? nullptr : orig.data(), orig.data(), opt.neighboursFrom, nrm, keep.data()},
                                    n, k, laid ? laidOrient : orient, opt, pos, localSpacing);
  if (order) *order = std::move(orig);
  return removed;
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

// The first `cap` points of pos[0..n) (in order) within `half` of c on every axis, into out
// (xyz-interleaved): blocks scanned on every core, a few at a time, until the cap is reached.
void pointsInCube(const double* pos, size_t n, const Eigen::Vector3d& c, double half, size_t cap, std::vector<double>& out) {
  out.clear();
  constexpr size_t kBlock = 1 << 14, kBlocks = 16;
  std::vector<double> found[kBlocks];
  for (size_t first = 0; first < n && out.size() < 3 * cap; first += kBlock * kBlocks) {
    tbb::parallel_for(size_t(0), kBlocks, [&](size_t b) {
      found[b].clear();
      const size_t lo = std::min(n, first + b * kBlock), hi = std::min(n, lo + kBlock);
      for (size_t i = lo; i < hi; ++i) {
        const Eigen::Vector3d p(&pos[3 * i]);
        if (((p - c).cwiseAbs().array() <= half).all()) found[b].insert(found[b].end(), {p.x(), p.y(), p.z()});
      }
    });
    for (size_t b = 0; b < kBlocks && out.size() < 3 * cap; ++b)
      out.insert(out.end(), found[b].begin(), found[b].begin() + long(std::min(found[b].size(), 3 * cap - out.size())));
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
    double lo[3], hi[3];
    pointBounds(pos, n, lo, hi);
    const size_t want = kMaxTree / 4;
    double side = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]}) * std::sqrt(double(want) / double(n));  // surfaces: area ~ side^2
    // The sub-cubes one after the other (each starts from the side the one before settled on),
    // then their distances on every core, appended in order.
    std::vector<double> sub[4];
    double inner[4];
    Eigen::Vector3d centre[4];
    for (int seed = 0; seed < 4; ++seed) {
      const Eigen::Vector3d& c = centre[seed] = Eigen::Vector3d(&pos[3 * ((2 * seed + 1) * n / 8)]);
      for (int attempt = 0; attempt < 8; ++attempt) {
        pointsInCube(pos, n, c, side / 2, 4 * want + 1, sub[seed]);
        const size_t m = sub[seed].size() / 3;
        if (m < want / 4) side *= 1.6;
        else if (m > 4 * want) side /= 1.6;
        else break;
      }
      inner[seed] = side / 4;
    }
    std::vector<double> ds[4], areas[4];
    tbb::parallel_for(0, 4, [&](int seed) {
      const Eigen::Vector3d& c = centre[seed];
      const std::vector<double>& sb = sub[seed];
      nearestDistances(sb.data(), sb.size() / 3, samples / 4, [&](size_t a) {
        return ((Eigen::Vector3d(&sb[3 * a]) - c).cwiseAbs().array() <= inner[seed]).all();
      }, ds[seed], areas[seed]);
    });
    for (int seed = 0; seed < 4; ++seed) {
      d.insert(d.end(), ds[seed].begin(), ds[seed].end());
      area.insert(area.end(), areas[seed].begin(), areas[seed].end());
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
