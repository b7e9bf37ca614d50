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

void MarginFinder::normalField(const double* xyz, const float* hints, size_t m, double radius, float* out,
                               const TexelFrame* tile) const {
  std::copy(hints, hints + 3 * m, out);
  if (!index_ || m == 0) return;
  if (tile && radius > 0 && tile->du > 0 && tile->dv > 0) return tileField(xyz, hints, m, radius, out, *tile);
  const double r2 = radius * radius;
  std::vector<std::pair<double, uint32_t>> near;
  for (size_t i = 0; i < m; ++i) {
    index_->grid.within(&xyz[3 * i], radius, near);
    fieldAt(near.data(), near.size(), r2, &hints[3 * i], &out[3 * i]);
  }
}

void MarginFinder::fieldAt(const std::pair<double, uint32_t>* near, size_t count, double r2, const float* hintF,
                           float* out) const {
  const Eigen::Vector3d hint(hintF[0], hintF[1], hintF[2]);
  // The sum in scalars, each component as Eigen's q * q * nn added it (an Eigen vector sum went
  // through the stack).
  double sx = 0, sy = 0, sz = 0;
  for (size_t a = 0; a < count; ++a) {
    const auto& [d2, j] = near[a];
    const float* n = &nrm_[3 * size_t(j)];
    const Eigen::Vector3d nn(n[0], n[1], n[2]);
    if (!(nn.dot(hint) > 0.5)) continue;
    const double q = 1 - d2 / r2;
    if (!(q > 0)) continue;
    const double w = q * q;
    sx += w * nn.x(), sy += w * nn.y(), sz += w * nn.z();
  }
  Eigen::Vector3d sum(sx, sy, sz);
  if (sum.norm() > 0) {
    sum.normalize();
    for (int a = 0; a < 3; ++a) out[a] = float(sum[a]);
  }
}

// A point within the radius of a texel's centre is within it in the tile's plane and along its
// normal too: it lies in the tile's height range grown by the radius, in a bin (a square of
// texels about the radius wide, the grid extended past the tile) that the texel's square of side
// twice the radius meets. Both tests carry slack for rounding; what a texel keeps is decided by
// the distance computed as GridKnn::within computes it, in the order it sorts them.
void MarginFinder::tileField(const double* xyz, const float* hints, size_t m, double radius, float* out,
                             const TexelFrame& tile) const {
  const double r2 = radius * radius;
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
  std::vector<double> ax(binned.size()), ay(binned.size()), az(binned.size());
  for (size_t c = 0; c < cand.size(); ++c)
    if (binOf[c] >= 0) {
      const uint32_t slot = fill[size_t(binOf[c])]++;
      binned[slot] = cand[c];
      const double* p = &pos_[3 * size_t(cand[c])];
      ax[slot] = p[0], ay[slot] = p[1], az[slot] = p[2];
    }
  // A texel reads the bins its centre's square of side 2 radius meets (a hundredth of a bin of
  // slack for rounding).
  auto range = [](double c, double s, int64_t pad, int64_t n, double r, int64_t& b0, int64_t& b1) {
    b0 = std::max<int64_t>(0, int64_t(std::floor((c - r) / s - 0.01)) + pad);
    b1 = std::min<int64_t>(n - 1, int64_t(std::floor((c + r) / s + 0.01)) + pad);
  };
  std::vector<double> d2(binned.size());
  std::vector<std::pair<double, uint32_t>> near(binned.size() + 1);
  for (size_t k = 0; k < m; ++k) {
    const size_t ti = tile.texel[k] % size_t(tile.width), tj = tile.texel[k] / size_t(tile.width);
    int64_t u0, u1, v0, v1;
    range((double(ti) + 0.5) * tile.du, su, Pu, BW, radius, u0, u1);
    range((double(tj) + 0.5) * tile.dv, sv, Pv, BH, radius, v0, v1);
    const double qx = xyz[3 * k], qy = xyz[3 * k + 1], qz = xyz[3 * k + 2];
    size_t count = 0;
    for (int64_t bj = v0; bj <= v1; ++bj) {
      const uint32_t a0 = start[size_t(bj * BW + u0)], a1 = start[size_t(bj * BW + u1) + 1];
      for (uint32_t a = a0; a < a1; ++a) {
        const double dx = ax[a] - qx, dy = ay[a] - qy, dz = az[a] - qz;
        d2[a] = dx * dx + dy * dy + dz * dz;
      }
      for (uint32_t a = a0; a < a1; ++a) {  // branch-free: every one written, those within advance
        near[count] = {d2[a], binned[a]};
        count += d2[a] <= r2;
      }
    }
    std::sort(near.begin(), near.begin() + long(count));
    fieldAt(near.data(), count, r2, &hints[3 * k], &out[3 * k]);
  }
}

}  // namespace sa
