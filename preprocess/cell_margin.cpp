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
// An exact sum is the same in any order: a texel that reads its tile's bins and a query that
// reads the grid's cells get the same normal without sorting their points first, and a tile's
// texels sum two points at a time.
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

// The same terms two points at a time (GCC's vector extension; each lane computes what add
// computes, in the same order): the points [a0, a1) of per-axis arrays.
typedef double V2 __attribute__((vector_size(16)));
typedef long long M2 __attribute__((vector_size(16)));

inline V2 load2(const double* p) {
  V2 v;
  __builtin_memcpy(&v, p, sizeof v);
  return v;
}

void addRange(const double* ax, const double* ay, const double* az, const double* nx, const double* ny, const double* nz,
              uint32_t a0, uint32_t a1, const double* q, double inv, const double* h, FieldSum& sum) {
  const V2 qx = {q[0], q[0]}, qy = {q[1], q[1]}, qz = {q[2], q[2]}, hx = {h[0], h[0]}, hy = {h[1], h[1]}, hz = {h[2], h[2]};
  const V2 one = {1, 1}, zero = {0, 0}, half = {0.5, 0.5}, fix = {kFieldFix, kFieldFix}, rnd = {kRound, kRound}, iv = {inv, inv};
  V2 sx = zero, sy = zero, sz = zero;
  uint32_t a = a0;
  for (; a + 2 <= a1; a += 2) {
    const V2 dx = load2(ax + a) - qx, dy = load2(ay + a) - qy, dz = load2(az + a) - qz;
    const V2 d2 = dx * dx + dy * dy + dz * dz;
    const V2 px = load2(nx + a), py = load2(ny + a), pz = load2(nz + a);
    const V2 qq = one - d2 * iv, w = qq * qq * fix;
    const M2 keep = (qq > zero) & (px * hx + py * hy + pz * hz > half);
    sx += (V2)(keep & (M2)((w * px + rnd) - rnd));
    sy += (V2)(keep & (M2)((w * py + rnd) - rnd));
    sz += (V2)(keep & (M2)((w * pz + rnd) - rnd));
  }
  sum.x += sx[0] + sx[1], sum.y += sy[0] + sy[1], sum.z += sz[0] + sz[1];
  for (; a < a1; ++a) {
    const double dx = ax[a] - q[0], dy = ay[a] - q[1], dz = az[a] - q[2];
    sum.add(dx * dx + dy * dy + dz * dz, inv, nx[a], ny[a], nz[a], h);
  }
}

}  // namespace

void MarginFinder::normalField(const double* xyz, const float* hints, size_t m, double radius, float* out,
                               const TexelFrame* tile) const {
  std::copy(hints, hints + 3 * m, out);
  if (!index_ || m == 0) return;
  if (tile && radius > 0 && tile->du > 0 && tile->dv > 0) return tileField(xyz, hints, m, radius, out, *tile);
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

// A point within the radius of a texel's centre is within it in the tile's plane and along its
// normal too: it lies in the tile's height range grown by the radius, in a bin (a square of
// texels about the radius wide, the grid extended past the tile) that the texel's square of side
// twice the radius meets. Both tests carry slack for rounding; what a texel keeps is decided by
// the distance computed as GridKnn::within computes it.
void MarginFinder::tileField(const double* xyz, const float* hints, size_t m, double radius, float* out,
                             const TexelFrame& tile) const {
  const double inv = 1 / (radius * radius);
  // The texel centres' box in the frame.
  const Eigen::Vector3d w = tile.u.cross(tile.v);
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (size_t k = 0; k < m; ++k) {
    const Eigen::Vector3d d = Eigen::Vector3d(&xyz[3 * k]) - tile.origin;
    const Eigen::Vector3d f(d.dot(tile.u), d.dot(tile.v), d.dot(w));
    lo = lo.cwiseMin(f), hi = hi.cwiseMax(f);
  }
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
  // Bins: squares of S x S texels, S about the radius, with P bins past the tile on every side.
  const double su = std::max(1.0, std::floor(radius / tile.du)) * tile.du, sv = std::max(1.0, std::floor(radius / tile.dv)) * tile.dv;
  const int64_t Pu = int64_t(std::ceil(radius / su)) + 1, Pv = int64_t(std::ceil(radius / sv)) + 1;
  const int64_t BW = int64_t(std::ceil(tile.width * tile.du / su)) + 2 * Pu, BH = int64_t(std::ceil(tile.height * tile.dv / sv)) + 2 * Pv;
  std::vector<int64_t> binOf(cand.size(), -1);
  std::vector<uint32_t> start(size_t(BW * BH) + 1, 0);
  for (size_t c = 0; c < cand.size(); ++c) {
    const Eigen::Vector3d d = Eigen::Vector3d(&pos_[3 * size_t(cand[c])]) - tile.origin;
    const double pw = d.dot(w);
    if (!(pw >= lo.z() - grow && pw <= hi.z() + grow)) continue;  // off the tile's heights
    const double bu = std::floor((d.dot(tile.u) - tile.u0) / su) + double(Pu), bv = std::floor((d.dot(tile.v) - tile.v0) / sv) + double(Pv);
    if (!(bu >= 0 && bv >= 0 && bu < double(BW) && bv < double(BH))) continue;
    binOf[c] = int64_t(bv) * BW + int64_t(bu);
    ++start[size_t(binOf[c]) + 1];
  }
  for (size_t b = 1; b < start.size(); ++b) start[b] += start[b - 1];
  // Each bin's points and their positions side by side, one array per axis (a texel reads a
  // row of bins in turn, its distances in one loop the compiler vectorizes).
  std::vector<uint32_t> binned(start.back()), fill(start.begin(), start.end() - 1);
  std::vector<double> ax(binned.size()), ay(binned.size()), az(binned.size()), nx(binned.size()), ny(binned.size()),
      nz(binned.size());
  for (size_t c = 0; c < cand.size(); ++c)
    if (binOf[c] >= 0) {
      const uint32_t slot = fill[size_t(binOf[c])]++;
      binned[slot] = cand[c];
      const double* p = &pos_[3 * size_t(cand[c])];
      ax[slot] = p[0], ay[slot] = p[1], az[slot] = p[2];
      const float* q = &nrm_[3 * size_t(cand[c])];
      nx[slot] = q[0], ny[slot] = q[1], nz[slot] = q[2];
    }
  // A texel reads the bins its centre's square of side 2 radius meets (a hundredth of a bin of
  // slack for rounding).
  auto range = [](double c, double s, int64_t pad, int64_t n, double r, int64_t& b0, int64_t& b1) {
    b0 = std::max<int64_t>(0, int64_t(std::floor((c - r) / s - 0.01)) + pad);
    b1 = std::min<int64_t>(n - 1, int64_t(std::floor((c + r) / s + 0.01)) + pad);
  };
  for (size_t k = 0; k < m; ++k) {
    const size_t ti = tile.texel[k] % size_t(tile.width), tj = tile.texel[k] / size_t(tile.width);
    int64_t u0, u1, v0, v1;
    range((double(ti) + 0.5) * tile.du, su, Pu, BW, radius, u0, u1);
    range((double(tj) + 0.5) * tile.dv, sv, Pv, BH, radius, v0, v1);
    const double h[3] = {hints[3 * k], hints[3 * k + 1], hints[3 * k + 2]};
    FieldSum sum;
    for (int64_t bj = v0; bj <= v1; ++bj)  // the distances as GridKnn::within computes them
      addRange(ax.data(), ay.data(), az.data(), nx.data(), ny.data(), nz.data(), start[size_t(bj * BW + u0)],
               start[size_t(bj * BW + u1) + 1], &xyz[3 * k], inv, h, sum);
    sum.store(&out[3 * k]);
  }
}

}  // namespace sa
