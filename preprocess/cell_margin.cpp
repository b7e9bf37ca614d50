#include "preprocess/cell_margin.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>

#include "preprocess/grid_knn.h"
#include "preprocess/normals.h"

namespace sa {

struct MarginFinder::Index {
  GridKnn grid;
  Index(const double* pos, size_t n, double spacing)
      : grid(pos, n, GridKnn::cellFor(spacing > 0 ? spacing : estimateSpacing(pos, n).area, 24)) {}
};

MarginFinder::MarginFinder(const double* pos, const float* nrm, size_t n, double spacing) : pos_(pos), nrm_(nrm) {
  if (n > 0) index_ = std::make_unique<Index>(pos, n, spacing);
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

namespace {

// The field's sums exact: each term w * n is rounded to a multiple of 2^-26 (far below a float
// normal's precision), so every partial sum of up to 2^27 terms is a double without rounding.
// An exact sum is the same in any order: a tile whose points add their terms to the texels they
// reach (tileField) and a query that sums the points of the grid's cells (normalField) get the
// same normal, and neither sorts its points first.
constexpr double kFieldFix = 67108864.0;       // 2^26
constexpr double kRound = 6755399441055744.0;  // 1.5 * 2^52: (x + kRound) - kRound rounds x to an integer

struct FieldSum {
  double x = 0, y = 0, z = 0;
  // A point at squared distance d2 with unit normal n, in the field of radius 1 / sqrt(inv) at a
  // place whose hint is h: weight (1 - d2 * inv)^2 where its normal agrees with h (dot > 0.5).
  void add(double d2, double inv, double nx, double ny, double nz, const double* h) {
    const double q = 1 - d2 * inv, w = q * q * kFieldFix;
    const bool keep = q > 0 && nx * h[0] + ny * h[1] + nz * h[2] > 0.5;
    x += keep ? (w * nx + kRound) - kRound : 0.0;
    y += keep ? (w * ny + kRound) - kRound : 0.0;
    z += keep ? (w * nz + kRound) - kRound : 0.0;
  }
  // The sum's direction into out; out is left as it is (the hint) where the sum is zero.
  void store(float* out) const {
    Eigen::Vector3d v{x, y, z};
    if (v.norm() > 0) {
      v.normalize();
      for (int a = 0; a < 3; ++a) out[a] = float(v[a]);
    }
  }
};

}  // namespace

void MarginFinder::normalField(const double* xyz, const float* hints, size_t m, double radius, float* out) const {
  std::copy(hints, hints + 3 * m, out);
  if (!index_ || m == 0) return;
  const double inv = 1 / (radius * radius);
  std::vector<std::pair<double, uint32_t>> near;
  for (size_t i = 0; i < m; ++i) {
    index_->grid.within(&xyz[3 * i], radius, near, false);  // any order: the sum is exact
    const double h[3] = {hints[3 * i], hints[3 * i + 1], hints[3 * i + 2]};
    FieldSum sum;
    for (const auto& [d2, j] : near) {
      const float* n = &nrm_[3 * size_t(j)];
      sum.add(d2, inv, n[0], n[1], n[2], h);
    }
    sum.store(&out[3 * i]);
  }
}

// Each of the chunk's points near the tile adds its term to the texels it can reach, instead of
// each texel looking for its points: a point within the radius of a texel's surface point is
// within it in the tile's plane and along its normal too, so it lies in the tile's height range
// grown by the radius and the texel's centre lies in the point's square of side twice the radius
// (both tests with slack for rounding). Whether it counts is decided by the distance computed as
// GridKnn::within computes it, and the exact sums make the order of the terms irrelevant.
void MarginFinder::tileField(const TexelFrame& tile, double radius, TileTexels& t) const {
  if (!index_ || !(radius > 0) || !(tile.du > 0) || !(tile.dv > 0) || tile.width <= 0 || tile.height <= 0) return;
  const int W = tile.width, H = tile.height;
  const size_t n = size_t(W) * size_t(H);
  auto covered = [&](size_t k) { return t.hx[k] != 0 || t.hy[k] != 0 || t.hz[k] != 0; };
  // The covered texels' box in the frame.
  const Eigen::Vector3d w = tile.u.cross(tile.v);
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (size_t k = 0; k < n; ++k) {
    if (!covered(k)) continue;
    const Eigen::Vector3d d = Eigen::Vector3d(t.x[k], t.y[k], t.z[k]) - tile.origin;
    const Eigen::Vector3d f(d.dot(tile.u), d.dot(tile.v), d.dot(w));
    lo = lo.cwiseMin(f), hi = hi.cwiseMax(f);
  }
  if (!(lo.x() <= hi.x())) return;  // nothing covered
  // The world box around the frame's box grown by the radius (and a little for rounding).
  const double grow = radius * (1 + 1e-6) + 1e-6 * (tile.du + tile.dv);
  Eigen::Vector3d wlo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), whi = -wlo;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d f((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(), (c & 4) ? hi.z() : lo.z());
    const Eigen::Vector3d x = tile.origin + tile.u * f.x() + tile.v * f.y() + w * f.z();
    wlo = wlo.cwiseMin(x), whi = whi.cwiseMax(x);
  }
  wlo.array() -= grow, whi.array() += grow;
  std::vector<uint32_t> cand;
  index_->grid.cellsMeeting(wlo.data(), whi.data(), cand);
  const double inv = 1 / (radius * radius);
  std::vector<double> sx(n, 0.0), sy(n, 0.0), sz(n, 0.0);
  // The texels whose centres u0 + (i + 0.5) du lie within c -+ radius (a hundredth of a texel of
  // slack), clamped to the tile; false when none.
  auto range = [&](double c, double u0, double du, int count, int& i0, int& i1) {
    const double a = std::ceil((c - radius - u0) / du - 0.5 - 0.01), b = std::floor((c + radius - u0) / du - 0.5 + 0.01);
    if (!(a <= b && b >= 0 && a <= double(count - 1))) return false;
    i0 = a < 0 ? 0 : int(a);
    i1 = b > double(count - 1) ? count - 1 : int(b);
    return true;
  };
  constexpr size_t kAhead = 8;  // the candidates lie all over the chunk: their loads are fetched ahead
  for (size_t a = 0; a < cand.size(); ++a) {
    if (a + kAhead < cand.size()) {
      __builtin_prefetch(&pos_[3 * size_t(cand[a + kAhead])]);
      __builtin_prefetch(&nrm_[3 * size_t(cand[a + kAhead])]);
    }
    const uint32_t c = cand[a];
    const double* p = &pos_[3 * size_t(c)];
    const Eigen::Vector3d d = Eigen::Vector3d(p) - tile.origin;
    const double pw = d.dot(w);
    if (!(pw >= lo.z() - grow && pw <= hi.z() + grow)) continue;  // off the tile's heights
    int i0, i1, j0, j1;
    if (!range(d.dot(tile.u), tile.u0, tile.du, W, i0, i1) || !range(d.dot(tile.v), tile.v0, tile.dv, H, j0, j1)) continue;
    const double px = p[0], py = p[1], pz = p[2];
    const double nx = nrm_[3 * size_t(c)], ny = nrm_[3 * size_t(c) + 1], nz = nrm_[3 * size_t(c) + 2];
    for (int j = j0; j <= j1; ++j) {
      const size_t row = size_t(j) * size_t(W);
      const double *X = &t.x[row], *Y = &t.y[row], *Z = &t.z[row];
      const float *HX = &t.hx[row], *HY = &t.hy[row], *HZ = &t.hz[row];
      double *SX = &sx[row], *SY = &sy[row], *SZ = &sz[row];
      for (int i = i0; i <= i1; ++i) {  // FieldSum::add's terms
        const double dx = px - X[i], dy = py - Y[i], dz = pz - Z[i];
        const double q = 1 - (dx * dx + dy * dy + dz * dz) * inv, wt = q * q * kFieldFix;
        const bool keep = (q > 0) & (nx * double(HX[i]) + ny * double(HY[i]) + nz * double(HZ[i]) > 0.5);
        SX[i] += keep ? (wt * nx + kRound) - kRound : 0.0;
        SY[i] += keep ? (wt * ny + kRound) - kRound : 0.0;
        SZ[i] += keep ? (wt * nz + kRound) - kRound : 0.0;
      }
    }
  }
  for (size_t k = 0; k < n; ++k) {
    if (!covered(k)) continue;
    float out[3] = {t.hx[k], t.hy[k], t.hz[k]};
    FieldSum{sx[k], sy[k], sz[k]}.store(out);
    t.hx[k] = out[0], t.hy[k] = out[1], t.hz[k] = out[2];
  }
}

}  // namespace sa
