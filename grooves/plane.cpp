// Groove detection in one planar region (MODES.md §4): splat -> robust low-pass -> residual ->
// multi-scale Hessian valleys (threshold from the measured noise) -> Steger centre lines ->
// hysteresis linking -> a V or U profile fitted to the raw points across each line; thin
// elongated uncovered strips become "gap" lines.
#include "grooves/plane.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>

#include <Eigen/Eigenvalues>

#include "grooves/raster.h"

namespace sa::grooves {
namespace {

struct Grid {
  double u0 = 0, v0 = 0, p = 1;  // origin and pitch (half a spacing)
  int w = 0, h = 0;
  Eigen::Vector2d toPixel(double u, double v) const { return {(u - u0) / p, (v - v0) / p}; }
  Eigen::Vector2d toPlane(const Eigen::Vector2d& px) const { return {u0 + px.x() * p, v0 + px.y() * p}; }
};

constexpr int kMaxGrid = 4096;

Grid makeGrid(const std::vector<Eigen::Vector3d>& pts, double s) {
  Grid g;
  g.p = s / 2;
  Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
  for (const Eigen::Vector3d& q : pts) {
    lo = lo.cwiseMin(q.head<2>());
    hi = hi.cwiseMax(q.head<2>());
  }
  g.u0 = lo.x();
  g.v0 = lo.y();
  g.w = std::min(kMaxGrid, int(std::ceil((hi.x() - lo.x()) / g.p)) + 1);
  g.h = std::min(kMaxGrid, int(std::ceil((hi.y() - lo.y()) / g.p)) + 1);
  return g;
}

// Gaussian splat (sigma one pixel = half a spacing) and coverage: a pixel is covered when a
// point lies within one spacing of it.
void splat(const std::vector<Eigen::Vector3d>& pts, const Grid& g, Img& S, Img& covered) {
  Img num(g.w, g.h), den(g.w, g.h);
  covered = Img(g.w, g.h);
  for (const Eigen::Vector3d& q : pts) {
    const Eigen::Vector2d c = g.toPixel(q.x(), q.y());
    const int x0 = int(std::floor(c.x())), y0 = int(std::floor(c.y()));
    for (int y = y0 - 1; y <= y0 + 2; ++y)
      for (int x = x0 - 1; x <= x0 + 2; ++x) {
        if (x < 0 || y < 0 || x >= g.w || y >= g.h) continue;
        const double d2 = (Eigen::Vector2d(x, y) - c).squaredNorm();
        const float wgt = float(std::exp(-0.5 * d2));
        num.at(x, y) += wgt * float(q.z());
        den.at(x, y) += wgt;
        if (d2 <= 4.0) covered.at(x, y) = 1;
      }
  }
  S = Img(g.w, g.h);
  for (size_t i = 0; i < S.a.size(); ++i) {
    if (den.a[i] <= 1e-3f) covered.a[i] = 0;
    S.a[i] = covered.a[i] > 0 ? num.a[i] / den.a[i] : 0.f;
  }
}

float robustStd(std::vector<float>& v) {
  if (v.empty()) return 0;
  const float m = median(v);
  for (float& x : v) x = std::fabs(x - m);
  return 1.4826f * median(v);
}

// The surface without its grooves: a masked low-pass that drops, over three rounds, the pixels
// far below it (the grooves themselves), so a groove does not pull its own rim down.
// One masked low-pass with "twicing" (Tukey): the low-pass of what the first left over is added
// back, so a curved surface is followed to O(sigma^4) instead of flattened by O(sigma^2).
Img twiced(const Img& S, const Img& mask, double sigma) {
  Img L = maskedLowPass(S, mask, sigma), rest(S.w, S.h);
  for (size_t i = 0; i < S.a.size(); ++i) rest.a[i] = S.a[i] - L.a[i];
  const Img c = maskedLowPass(rest, mask, sigma);
  for (size_t i = 0; i < S.a.size(); ++i) L.a[i] += c.a[i];
  return L;
}

Img robustLowPass(const Img& S, const Img& covered, double sigma) {
  Img mask = covered, L = twiced(S, mask, sigma);
  for (int round = 0; round < 3; ++round) {
    std::vector<float> r;
    for (size_t i = 0; i < S.a.size(); ++i)
      if (covered.a[i] > 0) r.push_back(S.a[i] - L.a[i]);
    const float sd = robustStd(r);
    for (size_t i = 0; i < S.a.size(); ++i) mask.a[i] = covered.a[i] > 0 && std::fabs(S.a[i] - L.a[i]) < 2.5f * sd ? 1.f : 0.f;
    L = twiced(S, mask, sigma);
  }
  return L;
}

// Chamfer distance (pixels) to the nearest uncovered pixel or the grid's edge: derivatives
// whose support reaches there see the data's border, not a groove.
Img edgeDistance(const Img& covered) {
  const int w = covered.w, h = covered.h;
  Img d(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool edge = x == 0 || y == 0 || x == w - 1 || y == h - 1 || covered.at(x, y) <= 0;
      d.at(x, y) = edge ? 0.f : 1e9f;
    }
  auto relax = [&](int x, int y, int dx, int dy, float c) {
    const int xx = x + dx, yy = y + dy;
    if (xx >= 0 && yy >= 0 && xx < w && yy < h) d.at(x, y) = std::min(d.at(x, y), d.at(xx, yy) + c);
  };
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      relax(x, y, -1, 0, 1.f), relax(x, y, 0, -1, 1.f), relax(x, y, -1, -1, 1.414f), relax(x, y, 1, -1, 1.414f);
    }
  for (int y = h - 1; y >= 0; --y)
    for (int x = w - 1; x >= 0; --x) {
      relax(x, y, 1, 0, 1.f), relax(x, y, 0, 1, 1.f), relax(x, y, 1, 1, 1.414f), relax(x, y, -1, 1, 1.414f);
    }
  return d;
}

struct Valley {
  float z = 0;                       // strength over the noise (0: not a centre-line pixel)
  Eigen::Vector2f pos, n;            // sub-pixel centre and unit normal across the valley
  int scale = -1;
};

// Per pixel the strongest valley centre over the scales (Steger: the residual's minimum across
// the valley lies within the pixel).
// Pixels closer than `keepOff` to the data's edge are left out at every scale (the low-pass
// sees one side there).
std::vector<Valley> valleys(const Img& R, const Img& covered, const std::vector<double>& scales, double keepOff) {
  std::vector<Valley> out(R.a.size());
  const Img edge = edgeDistance(covered);
  for (size_t si = 0; si < scales.size(); ++si) {
    const Derivatives d = gaussianDerivatives(R, scales[si]);
    std::vector<float> trace;
    for (size_t i = 0; i < R.a.size(); ++i)
      if (covered.a[i] > 0) trace.push_back(d.xx.a[i] + d.yy.a[i]);
    const float sd = std::max(robustStd(trace), 1e-20f);
    for (int y = 0; y < R.h; ++y)
      for (int x = 0; x < R.w; ++x) {
        const size_t i = size_t(y) * R.w + x;
        if (edge.a[i] < std::max(2 * scales[si], keepOff)) continue;
        const double a = d.xx.a[i], b = d.xy.a[i], c = d.yy.a[i];
        const double m = (a + c) / 2, q = std::sqrt((a - c) * (a - c) / 4 + b * b);
        const double l1 = m + q, l2 = m - q;
        if (l1 <= 0 || l1 < 2 * std::fabs(l2)) continue;
        const float z = float(l1 / sd);
        if (z <= out[i].z) continue;
        Eigen::Vector2d n = std::fabs(b) + std::fabs(l1 - a) > std::fabs(l1 - c) + std::fabs(b) ? Eigen::Vector2d(b, l1 - a)
                                                                                               : Eigen::Vector2d(l1 - c, b);
        if (n.norm() < 1e-20) n = a >= c ? Eigen::Vector2d(1, 0) : Eigen::Vector2d(0, 1);
        n.normalize();
        const double t = -(d.x.a[i] * n.x() + d.y.a[i] * n.y()) / l1;
        if (std::fabs(t * n.x()) > 0.5 || std::fabs(t * n.y()) > 0.5) continue;
        out[i].z = z;
        out[i].pos = Eigen::Vector2f(float(x + t * n.x()), float(y + t * n.y()));
        out[i].n = n.cast<float>();
        out[i].scale = int(si);
      }
  }
  return out;
}

// Steger's linking: from the strongest unused seed, follow the neighbour that best continues the
// line (distance + change of direction) among the three ahead, while it stays above `lo`.
std::vector<std::vector<int>> linkLines(const std::vector<Valley>& vs, int w, int h, float hi, float lo) {
  std::vector<int> seeds;
  for (size_t i = 0; i < vs.size(); ++i)
    if (vs[i].z >= hi) seeds.push_back(int(i));
  std::sort(seeds.begin(), seeds.end(), [&](int a, int b) { return vs[a].z > vs[b].z; });
  std::vector<uint8_t> used(vs.size(), 0);
  std::vector<std::vector<int>> lines;
  auto markSides = [&](int i) {
    const int x = i % w, y = i / w;
    for (int s : {-1, 1}) {
      const int xx = x + int(std::lround(s * vs[i].n.x())), yy = y + int(std::lround(s * vs[i].n.y()));
      if (xx >= 0 && yy >= 0 && xx < w && yy < h) used[size_t(yy) * w + xx] = 1;
    }
  };
  for (int seed : seeds) {
    if (used[seed]) continue;
    used[seed] = 1;
    std::vector<int> halves[2];
    for (int side = 0; side < 2; ++side) {
      int cur = seed;
      Eigen::Vector2f dir(-vs[seed].n.y(), vs[seed].n.x());
      if (side) dir = -dir;
      for (;;) {
        const int x = cur % w, y = cur / w;
        int best = -1;
        float bestCost = 1e30f;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            if (!dx && !dy) continue;
            const int xx = x + dx, yy = y + dy;
            if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
            const Eigen::Vector2f off = Eigen::Vector2f(float(dx), float(dy));
            if (off.normalized().dot(dir) < 0.38f) continue;  // the three neighbours ahead
            const int j = yy * w + xx;
            if (used[j] || vs[j].z < lo) continue;
            const float turn = std::acos(std::min(1.f, std::fabs(vs[j].n.dot(vs[cur].n))));
            const float cost = (vs[j].pos - vs[cur].pos).norm() + turn;
            if (cost < bestCost) bestCost = cost, best = j;
          }
        if (best < 0) break;
        Eigen::Vector2f nd(-vs[best].n.y(), vs[best].n.x());
        dir = nd.dot(dir) < 0 ? -nd : nd;
        markSides(cur);
        used[best] = 1;
        halves[side].push_back(best);
        cur = best;
      }
    }
    markSides(seed);
    std::vector<int> line(halves[1].rbegin(), halves[1].rend());
    line.push_back(seed);
    line.insert(line.end(), halves[0].begin(), halves[0].end());
    if (line.size() >= 3) lines.push_back(std::move(line));
  }
  return lines;
}

double shapeAt(bool rounded, double x) {
  const double a = std::fabs(x);
  if (a >= 1) return 0;
  return rounded ? std::sqrt(1 - a * a) : 1 - a;
}

// Offsets across the line (signed, world units) and residuals of the points beside its interior.
struct Across {
  std::vector<double> x, r;
};

// Points bucketed by 8 pixels for the profile fits.
struct Buckets {
  static constexpr int kPx = 8;
  int w = 0, h = 0;
  std::vector<std::vector<int>> lists;
  Buckets(const std::vector<Eigen::Vector3d>& pts, const Grid& g)
      : w((g.w + kPx - 1) / kPx), h((g.h + kPx - 1) / kPx), lists(size_t(w) * h) {
    for (size_t i = 0; i < pts.size(); ++i) {
      const Eigen::Vector2d px = g.toPixel(pts[i].x(), pts[i].y());
      const int bx = std::clamp(int(px.x()) / kPx, 0, w - 1), by = std::clamp(int(px.y()) / kPx, 0, h - 1);
      lists[size_t(by) * w + bx].push_back(int(i));
    }
  }
};

Across pointsAcross(const std::vector<Eigen::Vector2d>& line, const std::vector<Eigen::Vector3d>& pts,
                    const std::vector<float>& resid, const Buckets& b, const Grid& g, double reach) {
  Across a;
  const int bucketPx = Buckets::kPx, bw = b.w, bh = b.h;
  const auto& buckets = b.lists;
  Eigen::Vector2d lo = line[0], hi = line[0];
  for (const Eigen::Vector2d& q : line) lo = lo.cwiseMin(q), hi = hi.cwiseMax(q);
  const Eigen::Vector2d plo = g.toPixel(lo.x() - reach, lo.y() - reach), phi = g.toPixel(hi.x() + reach, hi.y() + reach);
  const int bx0 = std::max(0, int(plo.x()) / bucketPx), by0 = std::max(0, int(plo.y()) / bucketPx);
  const int bx1 = std::min(bw - 1, int(phi.x()) / bucketPx), by1 = std::min(bh - 1, int(phi.y()) / bucketPx);
  for (int by = by0; by <= by1; ++by)
    for (int bx = bx0; bx <= bx1; ++bx)
      for (int pi : buckets[size_t(by) * bw + bx]) {
        const Eigen::Vector2d q = pts[pi].head<2>();
        double best = 1e300, off = 0;
        bool interior = false;
        for (size_t k = 0; k + 1 < line.size(); ++k) {
          const Eigen::Vector2d ab = line[k + 1] - line[k];
          const double L2 = std::max(ab.squaredNorm(), 1e-300);
          const double t = (q - line[k]).dot(ab) / L2;
          const double tc = std::clamp(t, 0.0, 1.0);
          const double dist = (line[k] + tc * ab - q).norm();
          if (dist < best) {
            best = dist;
            const double cr = ab.x() * (q - line[k]).y() - ab.y() * (q - line[k]).x();
            off = cr / std::sqrt(L2);
            interior = !((k == 0 && t < 0) || (k + 2 == line.size() && t > 1));
          }
        }
        if (best <= reach && interior) {
          a.x.push_back(off);
          a.r.push_back(resid[pi]);
        }
      }
  return a;
}

// Least squares over shape (V, U), width and centre offset; depth in closed form.
void fitProfile(const Across& a, double s, const GrooveOptions& opt, PlaneLine& out) {
  double bestErr = 1e300;
  const double wMax = opt.maxWidth * s * 1.25;
  for (int rounded = 0; rounded < 2; ++rounded)
    for (double w = 0.5 * s; w <= wMax; w += 0.1 * s)
      for (double c = -0.75 * s; c <= 0.75 * s + 1e-9; c += 0.125 * s) {
        double rf = 0, ff = 0, rr = 0;
        for (size_t i = 0; i < a.x.size(); ++i) {
          const double f = shapeAt(rounded, (a.x[i] - c) / (w / 2));
          rf += a.r[i] * f;
          ff += f * f;
          rr += a.r[i] * a.r[i];
        }
        if (ff <= 0 || rf >= 0) continue;
        const double err = rr - rf * rf / ff;
        if (err < bestErr) {
          bestErr = err;
          out.width = w;
          out.depth = -rf / ff;
          out.shape = rounded ? "U" : "V";
        }
      }
  // Median cross-section in half-spacing bins over twice the width.
  const double bin = s / 2, reach = std::max(out.width, 2 * s);
  const int nb = int(std::ceil(reach / bin));
  std::vector<std::vector<float>> bins(size_t(2 * nb + 1));
  for (size_t i = 0; i < a.x.size(); ++i) {
    const int b = int(std::lround(a.x[i] / bin));
    if (std::abs(b) <= nb) bins[size_t(b + nb)].push_back(float(a.r[i]));
  }
  out.profile.clear();
  for (int b = -nb; b <= nb; ++b)
    if (!bins[size_t(b + nb)].empty()) out.profile.push_back({float(b * bin), median(bins[size_t(b + nb)])});
}

// Uncovered pixels with data on both sides within `reach` pixels along one of four directions:
// inside a crack, not the data's outside.
Img between(const Img& covered, int reach) {
  Img out(covered.w, covered.h);
  const int dirs[4][2] = {{1, 0}, {0, 1}, {1, 1}, {1, -1}};
  auto hits = [&](int x, int y, int dx, int dy) {
    for (int k = 1; k <= reach; ++k) {
      const int xx = x + k * dx, yy = y + k * dy;
      if (xx < 0 || yy < 0 || xx >= covered.w || yy >= covered.h) return false;
      if (covered.at(xx, yy) > 0) return true;
    }
    return false;
  };
  for (int y = 0; y < covered.h; ++y)
    for (int x = 0; x < covered.w; ++x) {
      if (covered.at(x, y) > 0) continue;
      for (const auto& d : dirs)
        if (hits(x, y, d[0], d[1]) && hits(x, y, -d[0], -d[1])) {
          out.at(x, y) = 1;
          break;
        }
    }
  return out;
}

// 4-connected components of the pixels set in `m`.
std::vector<std::vector<int>> components(const Img& m) {
  std::vector<std::vector<int>> out;
  std::vector<uint8_t> seen(m.a.size(), 0);
  std::vector<int> stack;
  for (int start = 0; start < int(m.a.size()); ++start) {
    if (m.a[start] <= 0 || seen[start]) continue;
    std::vector<int> members;
    stack.push_back(start);
    seen[start] = 1;
    while (!stack.empty()) {
      const int i = stack.back();
      stack.pop_back();
      members.push_back(i);
      const int x = i % m.w, y = i / m.w;
      const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
      for (int k = 0; k < 4; ++k) {
        if (nx[k] < 0 || ny[k] < 0 || nx[k] >= m.w || ny[k] >= m.h) continue;
        const int j = ny[k] * m.w + nx[k];
        if (m.a[j] <= 0 || seen[j]) continue;
        seen[j] = 1;
        stack.push_back(j);
      }
    }
    out.push_back(std::move(members));
  }
  return out;
}

// A component's centre line in 2-pixel slices along its principal axis (the median across per
// slice) and its median extent across; false unless thin and elongated.
bool stripLine(const std::vector<int>& members, int w, std::vector<Eigen::Vector2d>& line, double& widthPx,
               double& lengthPx) {
  Eigen::Vector2d mean(0, 0);
  for (int i : members) mean += Eigen::Vector2d(i % w, i / w);
  mean /= double(members.size());
  Eigen::Matrix2d C = Eigen::Matrix2d::Zero();
  for (int i : members) {
    const Eigen::Vector2d d = Eigen::Vector2d(i % w, i / w) - mean;
    C += d * d.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(C / double(members.size()));
  const Eigen::Vector2d axis = es.eigenvectors().col(1), across(-axis.y(), axis.x());
  std::map<int, std::vector<float>> slices;
  for (int i : members) {
    const Eigen::Vector2d d = Eigen::Vector2d(i % w, i / w) - mean;
    slices[int(std::floor(d.dot(axis) / 2))].push_back(float(d.dot(across)));
  }
  std::vector<float> extents;
  for (auto& [k, v] : slices) {
    const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
    extents.push_back(*hi - *lo + 1);
  }
  widthPx = median(extents);
  line.clear();
  for (auto& [k, v] : slices) {
    const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
    if (*hi - *lo + 1 > 2 * widthPx) continue;  // where the strip meets another hole
    line.push_back(mean + axis * (2 * k + 1) + across * double(median(v)));
  }
  lengthPx = 2.0 * double(line.size());
  return line.size() >= 2 && lengthPx >= 4 * widthPx;
}

// A crack's strip has dense data on both sides: at 2-8 pixels beside its edges at least 90 %
// of the pixels are covered. Sparse or unevenly sampled areas (scan lines, mesh vertices of
// varying density) are full of small holes there.
bool denseBeside(const Img& covered, const std::vector<Eigen::Vector2d>& line, double widthPx) {
  size_t hit = 0, total = 0;
  for (size_t k = 0; k + 1 < line.size(); ++k) {
    const Eigen::Vector2d t = (line[k + 1] - line[k]).normalized(), n(-t.y(), t.x());
    for (int side : {-1, 1})
      for (int o = 2; o <= 8; ++o) {
        const Eigen::Vector2d q = line[k] + n * (side * (widthPx / 2 + o));
        const int x = int(std::lround(q.x())), y = int(std::lround(q.y()));
        if (x < 0 || y < 0 || x >= covered.w || y >= covered.h) continue;
        ++total;
        hit += covered.at(x, y) > 0;
      }
  }
  return total > 0 && hit * 10 >= total * 9;
}

// Thin, elongated uncovered strips (a deep crack returns no points).
std::vector<std::vector<Eigen::Vector2d>> gapLines(const Img& covered, const Grid& g, double s, const GrooveOptions& opt,
                                                   std::vector<double>& widths) {
  std::vector<std::vector<Eigen::Vector2d>> out;
  const int reach = int(std::ceil(opt.maxWidth * s / g.p));
  const Img inside = between(covered, reach);
  // Uncovered pixels that are not between data: the data's outside.
  auto besideOutside = [&](int i) {
    const int x = i % g.w, y = i / g.w;
    if (x <= 1 || y <= 1 || x >= g.w - 2 || y >= g.h - 2) return true;
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx)
        if (covered.at(x + dx, y + dy) <= 0 && inside.at(x + dx, y + dy) <= 0) return true;
    return false;
  };
  for (const std::vector<int>& members : components(inside)) {
    if (members.size() < 6) continue;
    size_t border = 0;
    for (int i : members) border += besideOutside(i);
    if (border * 5 > members.size()) continue;  // notches along the data's edge, not a crack
    std::vector<Eigen::Vector2d> px;
    double widthPx = 0, lengthPx = 0;
    if (!stripLine(members, g.w, px, widthPx, lengthPx)) continue;
    if (widthPx < 2 || !denseBeside(covered, px, widthPx)) continue;
    // No point lies within a spacing of the strip, and the points beside a crack lie on average
    // a quarter spacing from its edge: the crack is about 0.75 spacing wider than the strip
    // (measured on jittered-grid scans of 2.5-5 spacing cracks).
    const double width = widthPx * g.p + 0.75 * s;
    if (lengthPx * g.p < opt.minLength * s || width > opt.maxWidth * s) continue;
    std::vector<Eigen::Vector2d> line;
    for (const Eigen::Vector2d& q : px) line.push_back(g.toPlane(q));
    out.push_back(std::move(line));
    widths.push_back(width);
  }
  return out;
}

// The region's surface without grooves, and every point's residual against it.
struct Surface {
  Grid g;
  Img S, covered, L;
  std::vector<float> resid;
  double noise = 0;
};

Surface surfaceOf(const std::vector<Eigen::Vector3d>& pts, double s, const GrooveOptions& opt) {
  Surface f;
  f.g = makeGrid(pts, s);
  splat(pts, f.g, f.S, f.covered);
  // The low-pass: sigma the widest groove's width, a window (about 6 sigma) 4-8 times as wide
  // as the grooves looked for.
  f.L = robustLowPass(f.S, f.covered, opt.maxWidth * s / f.g.p);
  f.resid.resize(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) {
    const Eigen::Vector2d px = f.g.toPixel(pts[i].x(), pts[i].y());
    f.resid[i] = float(pts[i].z() - f.L.bilinear(px.x(), px.y()));
  }
  // The noise from points well inside the region: near its border the low-pass sees one side.
  const Img edge = edgeDistance(f.covered);
  std::vector<float> inner;
  for (size_t i = 0; i < pts.size(); ++i) {
    const Eigen::Vector2d px = f.g.toPixel(pts[i].x(), pts[i].y());
    if (edge.bilinear(px.x(), px.y()) >= opt.maxWidth * s / f.g.p) inner.push_back(f.resid[i]);
  }
  if (inner.size() < 16) inner = f.resid;
  f.noise = robustStd(inner);
  return f;
}

// A line in the plane at the rim's height (the low-pass).
void liftToRim(const Surface& f, const std::vector<Eigen::Vector2d>& uv, PlaneLine& pl) {
  for (const Eigen::Vector2d& q : uv) {
    const Eigen::Vector2d px = f.g.toPixel(q.x(), q.y());
    pl.uvh.emplace_back(q.x(), q.y(), f.L.bilinear(px.x(), px.y()));
  }
}

}  // namespace

bool measureInPlane(const std::vector<Eigen::Vector3d>& pts, const std::vector<Eigen::Vector2d>& line, double s,
                    const GrooveOptions& opt, PlaneLine& out, double& noise) {
  if (pts.size() < 16 || line.size() < 2) return false;
  const Surface f = surfaceOf(pts, s, opt);
  noise = f.noise;
  const Buckets buckets(pts, f.g);
  const Across a = pointsAcross(line, pts, f.resid, buckets, f.g, opt.maxWidth * s);
  if (a.x.size() < 8) return false;
  fitProfile(a, s, opt, out);
  liftToRim(f, line, out);
  return true;
}

double sideEvidence(const std::vector<Eigen::Vector3d>& pts, double s, const GrooveOptions& opt) {
  if (pts.size() < 16) return 0;
  const Surface f = surfaceOf(pts, s, opt);
  std::vector<float> r = f.resid;
  std::sort(r.begin(), r.end());
  const float lo = r[size_t(0.005 * (r.size() - 1))], hi = r[size_t(0.995 * (r.size() - 1))], mid = r[r.size() / 2];
  return ((mid - lo) - (hi - mid)) / std::max(f.noise, 1e-30) * double(pts.size());
}

PlaneResult detectInPlane(const std::vector<Eigen::Vector3d>& pts, double s, const GrooveOptions& opt) {
  PlaneResult res;
  if (pts.size() < 16) return res;
  const Surface f = surfaceOf(pts, s, opt);
  const Grid& g = f.g;
  const Img& L = f.L;
  const Img& covered = f.covered;
  const std::vector<float>& resid = f.resid;
  res.noise = f.noise;
  Img R(g.w, g.h);
  for (size_t i = 0; i < R.a.size(); ++i) R.a[i] = covered.a[i] > 0 ? f.S.a[i] - L.a[i] : 0.f;
  // Hessian scales: half-widths from the narrowest to the widest groove, doubling.
  std::vector<double> scales;
  for (double hw = opt.minWidth / 2; hw <= opt.maxWidth / 2 + 1e-9; hw *= 2) scales.push_back(hw * s / g.p);
  const std::vector<Valley> vs = valleys(R, covered, scales, 0.5 * opt.maxWidth * s / g.p);
  const auto chains = linkLines(vs, g.w, g.h, float(opt.threshold), float(opt.lowThreshold));
  const Buckets buckets(pts, g);
  auto lift = [&](const std::vector<Eigen::Vector2d>& uv, PlaneLine& pl) { liftToRim(f, uv, pl); };
  for (const std::vector<int>& chain : chains) {
    std::vector<Eigen::Vector2d> uv;
    double zsum = 0;
    for (int i : chain) {
      uv.push_back(g.toPlane(vs[i].pos.cast<double>()));
      zsum += vs[i].z;
    }
    PlaneLine pl;
    const Across a = pointsAcross(uv, pts, resid, buckets, g, opt.maxWidth * s);
    if (a.x.size() < 8) continue;
    fitProfile(a, s, opt, pl);
    if (pl.depth < std::max(opt.minDepth * s, 2 * res.noise)) continue;
    const double meanZ = zsum / chain.size();
    pl.confidence = std::clamp(1 - std::exp(-(meanZ - opt.lowThreshold) / opt.threshold), 0.0, 1.0);
    lift(uv, pl);
    res.lines.push_back(std::move(pl));
  }
  if (opt.gaps) {
    std::vector<double> widths;
    const auto gaps = gapLines(covered, g, s, opt, widths);
    for (size_t k = 0; k < gaps.size(); ++k) {
      PlaneLine pl;
      pl.shape = "gap";
      pl.width = widths[k];
      pl.depth = 0;
      pl.confidence = 0.5;
      lift(gaps[k], pl);
      res.lines.push_back(std::move(pl));
    }
  }
  return res;
}

}  // namespace sa::grooves
