#include "preprocess/octree.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace sa {
namespace {

Eigen::Vector3d anyPerpendicular(const Eigen::Vector3d& a) {
  Eigen::Vector3d t = std::abs(a.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  return a.cross(t).normalized();
}

}  // namespace

PlaneFit fitPlane(const double* pos, const float* nrm, const uint32_t* idx, size_t n, double cosMax,
                  double outlierFraction, const float* cone) {
  PlaneFit f;
  if (n == 0) return f;
  // Centroid and covariance relative to the first point (no cancellation at large offsets).
  const Eigen::Vector3d ref(&pos[3 * size_t(idx[0])]);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero(), nsum = Eigen::Vector3d::Zero();
  constexpr size_t kAhead = 16;  // prefetch distance: the points come in the file's order, all over the chunk
  for (size_t i = 0; i < n; ++i) {
    if (i + kAhead < n) {
      __builtin_prefetch(&pos[3 * size_t(idx[i + kAhead])]);
      __builtin_prefetch(&nrm[3 * size_t(idx[i + kAhead])]);
    }
    sum += Eigen::Vector3d(&pos[3 * size_t(idx[i])]) - ref;
    const float* q = &nrm[3 * size_t(idx[i])];
    nsum += Eigen::Vector3d(q[0], q[1], q[2]);
  }
  const Eigen::Vector3d mean = sum / double(n);
  f.centroid = ref + mean;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    if (i + kAhead < n) __builtin_prefetch(&pos[3 * size_t(idx[i + kAhead])]);
    Eigen::Vector3d d = Eigen::Vector3d(&pos[3 * size_t(idx[i])]) - ref - mean;
    cov += d * d.transpose();
  }
  cov /= double(n);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  const Eigen::Vector3d lambda = es.eigenvalues();  // ascending
  const double scale = std::max(lambda[2], 0.0);
  const Eigen::Vector3d meanNormal = nsum.norm() > 1e-12 ? Eigen::Vector3d(nsum.normalized()) : Eigen::Vector3d::UnitZ();
  if (n < 3 || es.info() != Eigen::Success || !(scale > 0) || lambda[1] <= 1e-9 * scale) {
    // Degenerate: one point, duplicates or a line. The plane is not determined by the
    // points; take W from the normals, orthogonal to the line if there is one.
    f.degenerate = true;
    Eigen::Vector3d w = meanNormal;
    if (scale > 0 && es.info() == Eigen::Success) {
      const Eigen::Vector3d line = es.eigenvectors().col(2);
      w -= line * line.dot(w);
      w = w.norm() > 1e-6 ? Eigen::Vector3d(w.normalized()) : anyPerpendicular(line);
      f.u = line;
    } else {
      f.u = anyPerpendicular(w);
    }
    f.w = w;
  } else {
    f.w = es.eigenvectors().col(0).normalized();
    f.u = es.eigenvectors().col(2).normalized();
    if (f.w.dot(nsum) < 0) f.w = -f.w;
  }
  f.u = (f.u - f.w * f.w.dot(f.u)).normalized();
  f.v = f.w.cross(f.u);
  // The height-field test (§3.1.2): every known normal must face the W side of the plane.
  f.minCos = 1;
  for (size_t i = 0; i < n; ++i) {
    if (i + kAhead < n) __builtin_prefetch(&nrm[3 * size_t(idx[i + kAhead])]);
    const float* q = &nrm[3 * size_t(idx[i])];
    const double len2 = double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2];
    if (!(len2 > 0.25)) continue;
    double c = (f.w.x() * q[0] + f.w.y() * q[1] + f.w.z() * q[2]) / std::sqrt(len2);
    if (cone && cone[idx[i]] > 0) c = std::cos(std::min(M_PI, std::acos(std::clamp(c, -1.0, 1.0)) + cone[idx[i]]));
    f.minCos = std::min(f.minCos, c);
    if (c < cosMax) ++f.violations;
  }
  f.heightField = f.violations <= static_cast<uint32_t>(outlierFraction * double(n));
  return f;
}

namespace {

// Whether heights h[0..m) (a bin's, in any order) leave a gap wider than `gap` once sorted. A bin
// whose range is at most the gap has none; two heights are their range apart; only the rest are
// sorted (scratch).
bool binSplits(const double* h, size_t m, double gap, std::vector<double>& scratch) {
  if (m < 2) return false;
  const auto [lo, hi] = std::minmax_element(h, h + m);
  if (!(*hi - *lo > gap)) return false;
  if (m == 2) return true;
  scratch.assign(h, h + m);
  std::sort(scratch.begin(), scratch.end());
  for (size_t k = 1; k < m; ++k)
    if (scratch[k] - scratch[k - 1] > gap) return true;
  return false;
}

}  // namespace

uint32_t countLayeredBins(const double* pos, const uint32_t* idx, size_t n, const PlaneFit& f, double bin,
                          double gap, uint32_t enough) {
  if (!(bin > 0) || !(gap > 0) || n < 2) return 0;
  // Every point's bin coordinates relative to the centroid (a cell spans at most a few million
  // bins per side) and height.
  std::vector<int64_t> bu(n), bv(n);
  std::vector<double> h(n);
  for (size_t i = 0; i < n; ++i) {
    if (i + 16 < n) __builtin_prefetch(&pos[3 * size_t(idx[i + 16])]);  // as fitPlane
    const Eigen::Vector3d d = Eigen::Vector3d(&pos[3 * size_t(idx[i])]) - f.centroid;
    bu[i] = static_cast<int64_t>(std::floor(d.dot(f.u) / bin));
    bv[i] = static_cast<int64_t>(std::floor(d.dot(f.v) / bin));
    h[i] = d.dot(f.w);
  }
  // The points grouped by bin: counted into the bins of their box when it has few enough (a
  // point cell's bins are two sample spacings wide: its box holds fewer bins than points), else
  // sorted by bin.
  const auto [u0, u1] = std::minmax_element(bu.begin(), bu.end());
  const auto [v0, v1] = std::minmax_element(bv.begin(), bv.end());
  const uint64_t W = uint64_t(*u1 - *u0) + 1, H = uint64_t(*v1 - *v0) + 1;
  std::vector<uint32_t> order(n), start;
  std::vector<uint64_t> key(n);
  if (W <= 4 * n && H <= 4 * n && W * H <= 4 * n + 64) {
    start.assign(W * H + 1, 0);
    for (size_t i = 0; i < n; ++i) ++start[(key[i] = uint64_t(bv[i] - *v0) * W + uint64_t(bu[i] - *u0)) + 1];
    for (size_t b = 0; b < W * H; ++b) start[b + 1] += start[b];
    std::vector<uint32_t> at(start.begin(), start.end() - 1);
    for (size_t i = 0; i < n; ++i) order[at[key[i]]++] = uint32_t(i);
  } else {
    for (size_t i = 0; i < n; ++i) key[i] = (uint64_t(bu[i] - *u0) << 32) ^ uint64_t(bv[i] - *v0), order[i] = uint32_t(i);
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return key[a] < key[b]; });
  }
  uint32_t layered = 0;
  std::vector<double> hs, scratch;
  for (size_t a = 0; a < n && layered < enough;) {
    size_t b = a;
    hs.clear();
    for (; b < n && key[order[b]] == key[order[a]]; ++b) hs.push_back(h[order[b]]);
    layered += binSplits(hs.data(), hs.size(), gap, scratch);
    a = b;
  }
  return layered;
}

uint32_t* partitionBelow(uint32_t* b, uint32_t* e, const double* pos, int axis, double mid) {
  auto below = [=](uint32_t i) { return pos[3 * size_t(i) + size_t(axis)] < mid; };
  const size_t n = size_t(e - b);
  constexpr size_t kBlock = 1 << 14;
  if (n < 4 * kBlock) return std::partition(b, e, below);
  const size_t blocks = (n + kBlock - 1) / kBlock;
  std::vector<uint8_t> in(n);
  std::vector<size_t> count(blocks);
  tbb::parallel_for(size_t(0), blocks, [&](size_t k) {
    size_t c = 0;
    for (size_t i = k * kBlock, end = std::min(n, i + kBlock); i < end; ++i) c += in[i] = below(b[i]);
    count[k] = c;
  });
  size_t split = 0;
  for (size_t c : count) split += c;
  // Per block, its indices on the wrong side: before the split, those that go right (counted
  // from the start); from the split, those that go left (counted from the end).
  std::vector<size_t> right(blocks + 1, 0), left(blocks + 1, 0);
  tbb::parallel_for(size_t(0), blocks, [&](size_t k) {
    size_t r = 0, l = 0;
    for (size_t i = k * kBlock, end = std::min(n, i + kBlock); i < end; ++i) {
      r += i < split && !in[i];
      l += i >= split && in[i];
    }
    right[k + 1] = r, left[k + 1] = l;
  });
  for (size_t k = 0; k < blocks; ++k) right[k + 1] += right[k], left[k + 1] += left[k];
  const size_t wrong = right[blocks];  // as many go each way
  std::vector<uint32_t> goRight(wrong), goLeft(wrong);
  tbb::parallel_for(size_t(0), blocks, [&](size_t k) {
    size_t r = right[k], l = wrong - left[k];  // goLeft is filled from its end: the last first
    for (size_t i = k * kBlock, end = std::min(n, i + kBlock); i < end; ++i) {
      if (i < split && !in[i]) goRight[r++] = uint32_t(i);
      if (i >= split && in[i]) goLeft[--l] = uint32_t(i);
    }
  });
  tbb::parallel_for(tbb::blocked_range<size_t>(0, wrong, kBlock), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t j = r.begin(); j != r.end(); ++j) std::swap(b[goRight[j]], b[goLeft[j]]);
  });
  return b + split;
}

namespace {

struct OctreeBuild {
  const double* pos;
  const float* nrm;
  const float* cone;
  uint32_t* idx;
  const OctreeParams& params;
  double cosMax, outliers;
  uint32_t minSplit;

  struct Item {
    uint32_t first, count;
    int level;
    Eigen::Vector3d min;
    double size;
  };

  // Subtrees of fewer points are built on the calling thread.
  static constexpr uint32_t kParallelPoints = 1u << 15;

  // The cells of one node's subtree, in the order a depth-first walk that visits the children
  // last to first emits them (the order of the serial build before it ran on every core).
  std::vector<OctreeCell> build(const Item& it) const {
    std::vector<OctreeCell> out;
    if (it.count == 0) return out;
    const bool canSplit = it.level < params.maxDepth && it.count >= minSplit;
    const bool tooLarge = params.maxLeafPoints && it.count > params.maxLeafPoints;
    // A node that splits whatever its test says needs no fit: at a chunk's root, the fit over
    // all its points ran on one core while the other waited.
    if (tooLarge && canSplit) return children(it);
    PlaneFit fit = fitPlane(pos, nrm, idx + it.first, it.count, cosMax, outliers, cone);
    if (fit.heightField &&
        countLayeredBins(pos, idx + it.first, it.count, fit, params.layerBin, params.layerGap, params.layeredBins) >=
            params.layeredBins) {
      fit.heightField = false;
      fit.layered = true;
    }
    if ((fit.heightField && !tooLarge) || !canSplit) {
      OctreeCell c;
      c.fit = fit;
      c.first = it.first;
      c.count = it.count;
      c.level = it.level;
      c.forced = !fit.heightField;
      c.cubeMin = it.min;
      c.cubeSize = it.size;
      out.push_back(c);
      return out;
    }
    return children(it);
  }

  // The cells of the node's eight children's subtrees.
  std::vector<OctreeCell> children(const Item& it) const {
    std::vector<OctreeCell> out;
    std::array<Item, 8> ch = split(it);
    std::array<std::vector<OctreeCell>, 8> sub;
    if (it.count >= kParallelPoints) {
      tbb::parallel_for(0, 8, [&](int c) { sub[size_t(c)] = build(ch[size_t(c)]); });
    } else {
      for (int c = 0; c < 8; ++c) sub[size_t(c)] = build(ch[size_t(c)]);
    }
    for (int c = 7; c >= 0; --c) out.insert(out.end(), sub[size_t(c)].begin(), sub[size_t(c)].end());
    return out;
  }

  // Partitions the node's points into its 8 children by the cube centre: x, then y, then z.
  std::array<Item, 8> split(const Item& it) const {
    const Eigen::Vector3d mid = it.min + Eigen::Vector3d::Constant(it.size / 2);
    uint32_t* b = idx + it.first;
    uint32_t* e = b + it.count;
    auto part = [&](uint32_t* from, uint32_t* to, int axis) { return partitionBelow(from, to, pos, axis, mid[axis]); };
    uint32_t* xs = part(b, e, 0);
    uint32_t* ranges[9];
    uint32_t* ys[2] = {part(b, xs, 1), part(xs, e, 1)};
    ranges[0] = b;
    ranges[2] = ys[0];
    ranges[4] = xs;
    ranges[6] = ys[1];
    ranges[8] = e;
    ranges[1] = part(ranges[0], ranges[2], 2);
    ranges[3] = part(ranges[2], ranges[4], 2);
    ranges[5] = part(ranges[4], ranges[6], 2);
    ranges[7] = part(ranges[6], ranges[8], 2);
    const double h = it.size / 2;
    std::array<Item, 8> ch;
    for (int c = 0; c < 8; ++c) {
      const int cx = c >> 2, cy = (c >> 1) & 1, cz = c & 1;
      ch[size_t(c)].first = static_cast<uint32_t>(ranges[c] - idx);
      ch[size_t(c)].count = static_cast<uint32_t>(ranges[c + 1] - ranges[c]);
      ch[size_t(c)].level = it.level + 1;
      ch[size_t(c)].min = it.min + Eigen::Vector3d(cx * h, cy * h, cz * h);
      ch[size_t(c)].size = h;
    }
    return ch;
  }
};

}  // namespace

// Children's subtrees are disjoint ranges of idx: they are built concurrently, and their cells
// concatenated in a fixed order, so the result does not depend on scheduling.
void buildOctree(const double* pos, const float* nrm, std::vector<uint32_t>& idx,
                 const Eigen::Vector3d& rootMin, double rootSize, int rootLevel, const OctreeParams& params,
                 std::vector<OctreeCell>& out, const float* cone) {
  const OctreeBuild b{pos, nrm, cone, idx.data(), params, std::cos(params.maxAngleDeg * M_PI / 180.0),
                      params.outlierFraction < 0 ? kPointOutlierFraction : params.outlierFraction,
                      params.minSplitPoints ? params.minSplitPoints : kPointMinSplit};
  std::vector<OctreeCell> cells = b.build({0, static_cast<uint32_t>(idx.size()), rootLevel, rootMin, rootSize});
  out.insert(out.end(), cells.begin(), cells.end());
}

}  // namespace sa
