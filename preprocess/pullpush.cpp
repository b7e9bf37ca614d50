#include "preprocess/pullpush.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "atlas/pack_format.h"
#include "atlas/tile_codec.h"
#include "preprocess/raster.h"

namespace sa {
namespace {

struct Level {
  int w = 0, h = 0;
  std::vector<float> weight;   // clamped to [0, 1] after normalizing
  std::vector<double> value;   // height (residual of the trend)
  std::vector<float> attr;     // nAttr channels per texel: colour (3) then normal (3), as present
};

// Least-squares quadratic w = q(u, v) over the samples, in coordinates normalised to the
// tile. Pull-push then interpolates the residual, so texels beyond the last sample (inside
// the coverage radius) follow the surface's slope and curvature instead of a flat average.
// Ridge-regularised: few or degenerate samples fall back toward lower order, never NaN.
struct Quadric {
  double cu = 0, cv = 0, su = 1, sv = 1;
  Eigen::Matrix<double, 6, 1> c = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::Matrix<double, 6, 1> basis(double u, double v) const {
    const double x = (u - cu) / su, y = (v - cv) / sv;
    Eigen::Matrix<double, 6, 1> b;
    b << 1, x, y, x * x, x * y, y * y;
    return b;
  }
  double operator()(double u, double v) const { return c.dot(basis(u, v)); }
  // Its value at every texel centre of g, row by row, with the coordinates' divisions once a
  // column and a row instead of once a texel. The terms are summed in the order the Release
  // build's two-lane Eigen dot above sums them, so the packs kept their bytes.
  std::vector<double> atTexels(const TileGrid& g) const {
    const int W = g.width, H = g.height;
    std::vector<double> xs(size_t(W), 0.0), out(size_t(W) * H);
    for (int x = 0; x < W; ++x) xs[size_t(x)] = (g.u0 + (x + 0.5) * g.du - cu) / su;
    for (int yi = 0; yi < H; ++yi) {
      const double y = (g.v0 + (yi + 0.5) * g.dv - cv) / sv, yc2 = y * c[2], y2c5 = y * y * c[5];
      double* row = &out[size_t(yi) * W];
      for (int xi = 0; xi < W; ++xi) {
        const double x = xs[size_t(xi)];
        const double even = (x * y * c[4] + yc2) + c[0];
        const double odd = (y2c5 + x * x * c[3]) + x * c[1];
        row[xi] = even + odd;
      }
    }
    return out;
  }
};

Quadric fitQuadric(const TileGrid& g, const double* u, const double* v, const double* w, size_t n) {
  Quadric q;
  q.cu = g.u0 + 0.5 * g.width * g.du;
  q.cv = g.v0 + 0.5 * g.height * g.dv;
  q.su = std::max(0.5 * g.width * g.du, 1e-300);
  q.sv = std::max(0.5 * g.height * g.dv, 1e-300);
  if (n == 0) return q;
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> rhs = Eigen::Matrix<double, 6, 1>::Zero();
  double mean = 0;
  for (size_t i = 0; i < n; ++i) mean += w[i];
  mean /= double(n);
  for (size_t i = 0; i < n; ++i) {
    const auto b = q.basis(u[i], v[i]);
    A.selfadjointView<Eigen::Lower>().rankUpdate(b);
    rhs += b * (w[i] - mean);
  }
  A = A.selfadjointView<Eigen::Lower>();
  const double ridge = 1e-6 * std::max(A.trace(), 1e-300);
  A.diagonal().array() += ridge;
  Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(A);
  Eigen::Matrix<double, 6, 1> c = ldlt.solve(rhs);
  if (ldlt.info() != Eigen::Success || !c.allFinite()) c.setZero();
  c[0] += mean;
  q.c = c;
  return q;
}

// Coverage in 3-D: a texel is covered when its reconstructed surface point (texel centre,
// surface height) lies within a sample's radius of it. A 2-D test (distance in the plane) would
// cover the interpolation across a height jump (roof to ground, deck to water, canopy to
// ground), which is surface where no point is; in 3-D such jumps stay open, as holes do.
// Stamped per sample over the texels of its disk, row by row.
std::vector<uint8_t> coverage3d(const TileGrid& g, const TileSamples& s, const std::vector<double>& surface,
                                double radius) {
  const int W = g.width, H = g.height;
  std::vector<uint8_t> covered(size_t(W) * H, 0);
  for (size_t i = 0; i < s.n; ++i) {
    const double r = radius * (s.scale ? std::max(s.scale[i], 1.0f) : 1.0f);
    const double ru = r / g.du, rv = r / g.dv, r2 = r * r;
    const int riv = static_cast<int>(std::ceil(rv));
    const double fx = (s.u[i] - g.u0) / g.du - 0.5, fy = (s.v[i] - g.v0) / g.dv - 0.5;
    if (!(fx > -ru - 1 && fy > -rv - 1 && fx < W + ru && fy < H + rv)) continue;
    const int cy = static_cast<int>(std::lround(fy));
    for (int y = std::max(0, cy - riv - 1); y <= std::min(H - 1, cy + riv + 1); ++y) {
      const double dy = (y - fy) / rv;
      const double span = 1.0 - dy * dy;
      if (span < 0) continue;
      const double half = std::sqrt(span) * ru;  // the disk's half-width on this row
      const int x0 = std::max(0, static_cast<int>(std::ceil(fx - half)));
      const int x1 = std::min(W - 1, static_cast<int>(std::floor(fx + half)));
      const double dv2 = std::pow((y - fy) * g.dv, 2), wi = s.w[i];
      // Branch-free, so the compiler codes it in vector lanes: a covered texel stays covered,
      // and a NaN surface (no height there) fails the comparison.
      uint8_t* row = &covered[size_t(y) * W];
      const double* srow = &surface[size_t(y) * W];
      for (int x = x0; x <= x1; ++x) {
        const double dh = srow[x] - wi, du = (x - fx) * g.du;
        row[x] |= uint8_t(du * du + dv2 + dh * dh <= r2);
      }
    }
  }
  return covered;
}

// Closes cracks one texel wide: an uncovered texel whose two neighbours along a row, column or
// diagonal are covered, where the surface continues between them. Scan rows on a steep flank
// lie about two coverage radii apart, and their disks leave a thin uncovered line between them:
// rows of dark dashes in a close-up of merged statue scans. Edges (covered on one side only) and
// anything wider stay open (two texels wide pushed autzen's pixels beyond 3 spacings from
// every point from 0.43 % to 0.98 %, one texel to 0.55 %).
void closeCracks(int W, int H, const std::vector<double>& surface, double tolerance, std::vector<uint8_t>& covered) {
  const std::vector<uint8_t> before = covered;
  const int dirs[4][2] = {{1, 0}, {0, 1}, {1, 1}, {1, -1}};
  auto at = [&](int x, int y) { return x >= 0 && y >= 0 && x < W && y < H && before[size_t(y) * W + x]; };
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const size_t t = size_t(y) * W + x;
      if (before[t] || std::isnan(surface[t])) continue;
      for (const auto& d : dirs) {
        if (!at(x - d[0], y - d[1]) || !at(x + d[0], y + d[1])) continue;
        const double ha = surface[size_t(y - d[1]) * W + (x - d[0])], hb = surface[size_t(y + d[1]) * W + (x + d[0])];
        if (std::abs(surface[t] - 0.5 * (ha + hb)) <= tolerance) {
          covered[t] = 1;
          break;
        }
      }
    }
}

// Closes small enclosed gaps: a connected uncovered region that does not reach the tile's
// border, every texel of which has a covered texel within `reach` in 3-D (texel centres on the
// reconstructed surface), is covered. Randomly spaced samples leave such gaps where no sample
// happens to fall within the coverage radius: pinholes that a far view shows as background
// dots on a closed surface. A real hole wider than twice `reach` keeps its inside open, and so
// does anything connected to the tile's border (scan edges, the cell's outside).
void closeSmallHoles(const TileGrid& g, const std::vector<double>& surface, double reach, std::vector<uint8_t>& covered) {
  const int W = g.width, H = g.height;
  if (W < 3 || H < 3 || !(reach > 0)) return;
  const int ri = static_cast<int>(std::ceil(reach / g.du)), rj = static_cast<int>(std::ceil(reach / g.dv));
  const std::vector<uint8_t> before = covered;  // closing one gap does not help another close
  std::vector<uint8_t> seen(covered.size(), 0);
  std::vector<size_t> region, stack;
  auto nearCovered = [&](size_t t) {
    const int x = static_cast<int>(t % size_t(W)), y = static_cast<int>(t / size_t(W));
    for (int j = std::max(0, y - rj); j <= std::min(H - 1, y + rj); ++j)
      for (int i = std::max(0, x - ri); i <= std::min(W - 1, x + ri); ++i) {
        const size_t c = size_t(j) * W + i;
        if (!before[c]) continue;
        const double du = (i - x) * g.du, dv = (j - y) * g.dv, dh = surface[c] - surface[t];
        if (du * du + dv * dv + dh * dh <= reach * reach) return true;
      }
    return false;
  };
  for (size_t start = 0; start < covered.size(); ++start) {
    if (covered[start] || seen[start]) continue;
    region.clear();
    stack.assign(1, start);
    seen[start] = 1;
    bool closable = true;
    while (!stack.empty()) {
      const size_t t = stack.back();
      stack.pop_back();
      region.push_back(t);
      const int x = static_cast<int>(t % size_t(W)), y = static_cast<int>(t / size_t(W));
      if (x == 0 || y == 0 || x == W - 1 || y == H - 1 || std::isnan(surface[t])) closable = false;
      const size_t next[4] = {t - 1, t + 1, t - size_t(W), t + size_t(W)};
      const bool inside[4] = {x > 0, x < W - 1, y > 0, y < H - 1};
      for (int k = 0; k < 4; ++k)
        if (inside[k] && !covered[next[k]] && !seen[next[k]]) {
          seen[next[k]] = 1;
          stack.push_back(next[k]);
        }
    }
    if (!closable) continue;
    if (!std::all_of(region.begin(), region.end(), nearCovered)) continue;
    for (const size_t t : region) covered[t] = 1;
  }
}

}  // namespace

namespace {

// The samples' attribute channels (colour, then normal) as floats.
struct Channels {
  int count = 0, color = -1, normal = -1;
  explicit Channels(const TileSamples& s) {
    if (s.rgb) color = count, count += 3;
    if (s.normal) normal = count, count += 3;
  }
  void add(const TileSamples& s, size_t i, double wt, float* dst) const {
    if (color >= 0)
      for (int k = 0; k < 3; ++k) dst[color + k] += float(wt * s.rgb[3 * i + k]);
    if (normal >= 0)
      for (int k = 0; k < 3; ++k) dst[normal + k] += float(wt * s.normal[3 * i + k]);
  }
};

Level makeLevel(int w, int h, int channels) {
  Level L;
  L.w = w;
  L.h = h;
  L.weight.assign(size_t(w) * h, 0.f);
  L.value.assign(size_t(w) * h, 0.0);
  L.attr.assign(size_t(w) * h * channels, 0.f);
  return L;
}

// Splat into the finest level: a smooth compact kernel of radius r (world units, times the
// sample's scale), or bilinear weights onto the four nearest texel centres when that is under a
// texel. With normals, a sample contributes its tangent plane at the texel, not its own height:
// planes are reconstructed exactly and the surface near a tile's edge, reached by few samples,
// follows their slope instead of bending toward the tile's trend.
void splat(const TileGrid& g, const TileSamples& s, const std::vector<double>& trendAt, double radius, const Channels& ch,
           Level& L) {
  const int W = g.width, H = g.height, C = ch.count;
  double gu = 0, gv = 0;  // the current sample's slope
  std::vector<double> across(size_t(std::max(W, 0))), plane(size_t(std::max(W, 0)));
  auto add = [&](size_t i, int x, int y, double wt) {
    const size_t t = size_t(y) * W + x;
    const double tu = g.u0 + (x + 0.5) * g.du, tv = g.v0 + (y + 0.5) * g.dv;
    L.weight[t] += float(wt);
    L.value[t] += wt * (s.w[i] + gu * (tu - s.u[i]) + gv * (tv - s.v[i]) - trendAt[t]);
    if (C) ch.add(s, i, wt, &L.attr[t * C]);
  };
  for (size_t i = 0; i < s.n; ++i) {
    gu = gv = 0;
    if (s.normal) {
      const float* n = &s.normal[3 * i];
      if (n[2] > 0.1f) {  // slopes up to about 84 degrees
        gu = -n[0] / n[2];
        gv = -n[1] / n[2];
      }
    }
    const double r = radius * (s.scale ? std::max(s.scale[i], 1.0f) : 1.0f);
    const bool kernel = r >= std::max(g.du, g.dv);
    const double rx = r / g.du, ry = r / g.dv;
    const double fx = (s.u[i] - g.u0) / g.du - 0.5, fy = (s.v[i] - g.v0) / g.dv - 0.5;
    if (!kernel) {
      if (!(fx > -1.0 && fy > -1.0 && fx < W && fy < H)) continue;
      const int ix = static_cast<int>(std::floor(fx)), iy = static_cast<int>(std::floor(fy));
      const double ax = fx - ix, ay = fy - iy;
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const int x = ix + dx, y = iy + dy;
          const double wt = (dx ? ax : 1 - ax) * (dy ? ay : 1 - ay);
          if (x >= 0 && y >= 0 && x < W && y < H && wt > 0) add(i, x, y, wt);
        }
      continue;
    }
    if (!(fx > -rx - 1 && fy > -ry - 1 && fx < W + rx && fy < H + ry)) continue;
    const int y0 = std::max(0, static_cast<int>(std::ceil(fy - ry))), y1 = std::min(H - 1, static_cast<int>(std::floor(fy + ry)));
    const int x0 = std::max(0, static_cast<int>(std::ceil(fx - rx))), x1 = std::min(W - 1, static_cast<int>(std::floor(fx + rx)));
    // The kernel's and the tangent plane's terms that depend on the column alone, once per
    // column: the same expressions as add's and the loop's, so the same sums.
    for (int x = x0; x <= x1; ++x) {
      const double dx = (x - fx) / rx, tu = g.u0 + (x + 0.5) * g.du;
      across[x] = 1 - dx * dx;
      plane[x] = s.w[i] + gu * (tu - s.u[i]);
    }
    for (int y = y0; y <= y1; ++y) {
      const double dy = (y - fy) / ry, tv = g.v0 + (y + 0.5) * g.dv, dv = gv * (tv - s.v[i]);
      for (int x = x0; x <= x1; ++x) {
        const double q = across[x] - dy * dy;
        if (!(q > 0)) continue;
        const double wt = q * q;
        const size_t t = size_t(y) * W + x;
        L.weight[t] += float(wt);
        L.value[t] += wt * (plane[x] + dv - trendAt[t]);
        if (C) ch.add(s, i, wt, &L.attr[t * C]);
      }
    }
  }
}

// The pyramid's steps below take the channel count C (0, 3 or 6) as a template argument: its
// loops over channels are then unrolled and coded in vector lanes, with each channel's
// arithmetic as before (the same bytes), about a fifth of pull-push's instructions fewer.

// Divides the sums by the weights; a weight of `full` or more is full confidence (1).
template <int C>
void normalize(Level& L, float full) {
  for (size_t t = 0; t < L.weight.size(); ++t) {
    if (L.weight[t] <= 0) continue;
    L.value[t] /= L.weight[t];
    for (int k = 0; k < C; ++k) L.attr[t * C + k] /= L.weight[t];
    L.weight[t] = std::min(L.weight[t] / full, 1.f);
  }
}

// Pull: average 2x2 children with their weights into the next coarser level.
template <int C>
Level pull(const Level& f) {
  Level c = makeLevel((f.w + 1) / 2, (f.h + 1) / 2, C);
  for (int y = 0; y < f.h; ++y)
    for (int x = 0; x < f.w; ++x) {
      const size_t ft = size_t(y) * f.w + x, ct = size_t(y / 2) * c.w + x / 2;
      const float wt = f.weight[ft];
      if (wt <= 0) continue;
      c.weight[ct] += wt;
      c.value[ct] += wt * f.value[ft];
      for (int k = 0; k < C; ++k) c.attr[ct * C + k] += wt * f.attr[ft * C + k];
    }
  normalize<C>(c, 1.f);
  return c;
}

// Push: fill a level's weak texels from the coarser level (bilinear). A texel's coarse
// neighbours and weights depend on its column and row alone: computed once per column and row.
template <int C>
void push(Level& f, const Level& c) {
  struct Tap {
    int i0, i1;  // the two coarse columns (rows)
    double a;    // the weight of the second
  };
  auto taps = [](int fine, int coarse) {
    std::vector<Tap> t(static_cast<size_t>(fine));
    for (int x = 0; x < fine; ++x) {
      // Position of this texel centre in the coarse grid.
      const double cx = std::clamp((x + 0.5) / 2.0 - 0.5, 0.0, double(coarse - 1));
      const int x0 = static_cast<int>(cx);
      t[size_t(x)] = {x0, std::min(x0 + 1, coarse - 1), cx - x0};
    }
    return t;
  };
  const std::vector<Tap> tx = taps(f.w, c.w), ty = taps(f.h, c.h);
  static_assert(C <= 6, "colour and normal at most");
  double acc[8];
  for (int y = 0; y < f.h; ++y) {
    const Tap& yt = ty[size_t(y)];
    const int ys[2] = {yt.i0, yt.i1};
    const double ay = yt.a;
    for (int x = 0; x < f.w; ++x) {
      const size_t ft = size_t(y) * f.w + x;
      const float wt = f.weight[ft];
      if (wt >= 1.f) continue;
      const Tap& xt = tx[size_t(x)];
      const int xs[2] = {xt.i0, xt.i1};
      const double ax = xt.a;
      double val = 0, ws = 0;
      std::fill(acc, acc + C, 0.0);
      for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) {
          const size_t ct = size_t(ys[j]) * c.w + xs[i];
          const double bw = (i ? ax : 1 - ax) * (j ? ay : 1 - ay) * c.weight[ct];
          ws += bw;
          val += bw * c.value[ct];
          for (int k = 0; k < C; ++k) acc[k] += bw * c.attr[ct * C + k];
        }
      if (ws <= 0) continue;
      f.value[ft] = wt * f.value[ft] + (1 - wt) * val / ws;
      for (int k = 0; k < C; ++k) f.attr[ft * C + k] = float(wt * f.attr[ft * C + k] + (1 - wt) * acc[k] / ws);
      f.weight[ft] = 1.f;
    }
  }
}

// Normalizes the splatted finest level (`full`: normalize's), then pulls to one texel and
// pushes back down.
template <int C>
void pullPush(std::vector<Level>& lv, float full) {
  normalize<C>(lv[0], full);
  while (lv.back().w > 1 || lv.back().h > 1) lv.push_back(pull<C>(lv.back()));
  for (int l = static_cast<int>(lv.size()) - 2; l >= 0; --l) push<C>(lv[size_t(l)], lv[size_t(l) + 1]);
}

}  // namespace

void pullPushTile(const TileGrid& g, const TileSamples& s, const SplatOptions& opt, TileOutput& out) {
  const int W = g.width, H = g.height;
  const Channels ch(s);
  const int C = ch.count;
  const std::vector<double> trend = fitQuadric(g, s.u, s.v, s.w, s.n).atTexels(g);
  std::vector<Level> lv;
  lv.push_back(makeLevel(W, H, C));
  splat(g, s, trend, opt.splatRadius, ch, lv[0]);
  // With the kernel, a texel a sample reaches at half the radius or nearer is fully known.
  const bool kernel = opt.splatRadius >= std::max(g.du, g.dv);
  const float full = kernel ? 0.5625f : 1.f;
  if (C == 0) pullPush<0>(lv, full);
  else if (C == 3) pullPush<3>(lv, full);
  else pullPush<6>(lv, full);
  // The reconstructed surface everywhere (push filled every texel the samples reach).
  const Level& L = lv[0];
  std::vector<double> surface(size_t(W) * H, NAN);
  for (size_t t = 0; t < surface.size(); ++t)
    if (L.weight[t] > 0) surface[t] = L.value[t] + trend[t];
  std::vector<uint8_t> covered = coverage3d(g, s, surface, opt.coverageRadius);
  closeCracks(W, H, surface, std::max(g.du, g.dv), covered);
  closeSmallHoles(g, surface, opt.gapReach, covered);
  out.wMin = g.wMin;
  out.wMax = g.wMax;
  if (opt.fitHeightRange)
    for (size_t t = 0; t < surface.size(); ++t)
      if (covered[t]) {
        out.wMin = std::min(out.wMin, surface[t]);
        out.wMax = std::max(out.wMax, surface[t]);
      }
  out.heights.assign(size_t(W) * H, 0);
  out.rgba.assign(ch.color >= 0 ? size_t(W) * H * 4 : 0, 0);
  out.normals.assign(ch.normal >= 0 ? size_t(W) * H * kNormalBytes : 0, 0);
  out.covered = 0;
  for (size_t t = 0; t < out.heights.size(); ++t) {
    if (!covered[t]) continue;
    out.heights[t] = encodeHeight(surface[t], out.wMin, out.wMax);
    ++out.covered;
    const float* a = L.attr.data() + t * C;  // C may be 0: no attribute channels
    if (ch.color >= 0) {
      for (int k = 0; k < 3; ++k) out.rgba[4 * t + k] = static_cast<uint8_t>(std::clamp(lroundNonNegative(a[ch.color + k]), 0L, 255L));
      out.rgba[4 * t + 3] = 255;
    }
    if (ch.normal >= 0) {
      const double f[3] = {a[ch.normal], a[ch.normal + 1], a[ch.normal + 2]};
      double w[3];
      g.toWorld(f, w);
      encodeNormal(w[0], w[1], w[2], &out.normals[kNormalBytes * t]);
    }
  }
}

uint32_t roundHeights(TileOutput& out, double maxStep) {
  const double range = out.wMax - out.wMin;
  if (!(range > 0) || !(maxStep > 0)) return 1;
  const double codes = maxStep / range * 65534.0;  // codes a step of maxStep spans
  uint32_t m = 1;
  while (m < 32768 && 2.0 * m <= codes) m *= 2;
  if (m == 1) return 1;
  const uint32_t top = 65534 / m * m;  // the largest multiple inside the range
  for (uint16_t& k : out.heights) {
    if (!k) continue;
    const uint32_t q = std::min((uint32_t(k) - 1 + m / 2) / m * m, top);
    k = static_cast<uint16_t>(q + 1);
  }
  return m;
}

namespace {

// snapToPyramid over the tile's covered texels.
size_t snap(std::vector<uint8_t>& texels, const std::vector<uint16_t>& heights, int W, int H, TexelLayout layout,
            const std::function<bool(const uint8_t*, const uint8_t*)>& close, std::vector<uint8_t>& payload) {
  payload.clear();
  if (texels.empty()) return 0;
  std::vector<uint8_t> cov(heights.size());
  for (size_t k = 0; k < heights.size(); ++k) cov[k] = heights[k] != 0;
  return snapToPyramid(texels.data(), cov.data(), uint32_t(W), uint32_t(H), layout, close, &payload);
}

}  // namespace

size_t snapNormals(TileOutput& out, int width, int height, double maxDegrees) {
  const double minCos = std::cos(maxDegrees * M_PI / 180);
  return snap(out.normals, out.heights, width, height, kNormalTexels, [&](const uint8_t* a, const uint8_t* b) {
    double na[3], nb[3];
    decodeNormal(a, na);
    decodeNormal(b, nb);
    return na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2] >= minCos;
  }, out.normalPyramid);
}

size_t snapColours(TileOutput& out, int width, int height, int maxLevels) {
  return snap(out.rgba, out.heights, width, height, kColorTexels, [&](const uint8_t* a, const uint8_t* b) {
    for (int c = 0; c < 3; ++c)
      if (std::abs(int(a[c]) - int(b[c])) > maxLevels) return false;
    return true;
  }, out.rgbaPyramid);
}

void rasterizeTile(const TileGrid& g, const double* tris, size_t triangleCount, double slack, double minCos,
                   const float* vertexNormals, TileOutput& out) {
  const int W = g.width, H = g.height;
  std::vector<double> best(size_t(W) * H, -INFINITY);
  std::vector<uint32_t> winner(best.size(), UINT32_MAX);
  std::vector<float> bary(vertexNormals ? 2 * best.size() : 0);
  // Pass 0: texels whose centre lies inside a triangle, exactly. Pass 1: the texels a triangle
  // touches within half a texel diagonal but whose centre no triangle holds, from the plane of
  // the triangle continued there: coverage then has no sub-texel gaps along the edge of the
  // triangles a cell holds, where a neighbouring cell takes over.
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<uint8_t> exact;
    if (pass == 1) {
      exact.resize(best.size());
      for (size_t k = 0; k < best.size(); ++k) exact[k] = best[k] != -INFINITY;
    }
    for (size_t t = 0; t < triangleCount; ++t) {
      const double* p = tris + 9 * t;
      // One-sided: a triangle facing away from +W (by its winding, as the mesh's vertex
      // normals are), or nearly edge-on, is not part of this height field (the far side of a
      // fold, the other face of an edge): kept, its largest w would cover the surface where
      // the tile reaches past the cell's own vertices.
      const Eigen::Vector3d e1(p[3] - p[0], p[4] - p[1], p[5] - p[2]), e2(p[6] - p[0], p[7] - p[1], p[8] - p[2]);
      const Eigen::Vector3d fn = e1.cross(e2);
      if (!(fn.z() > minCos * fn.norm())) continue;
      double x[3], y[3], z[3];
      for (int k = 0; k < 3; ++k) {
        x[k] = (p[3 * k] - g.u0) / g.du;
        y[k] = (p[3 * k + 1] - g.v0) / g.dv;
        z[k] = p[3 * k + 2];
      }
      rasterizeTriangle(x, y, W, H, [&](int px, int py, double b0, double b1, double b2) {
        const size_t k = size_t(py) * W + px;
        if (pass == 1 && exact[k]) return;
        const double wz = b0 * z[0] + b1 * z[1] + b2 * z[2];
        if (wz < g.wMin - slack || wz > g.wMax + slack) return;
        if (wz > best[k]) {
          best[k] = wz;
          winner[k] = static_cast<uint32_t>(t);
          if (vertexNormals) {
            bary[2 * k] = float(b0);
            bary[2 * k + 1] = float(b1);
          }
        }
      }, pass == 0 ? 0.0 : 0.7072);
    }
  }
  out.heights.assign(size_t(W) * H, 0);
  out.wMin = g.wMin;
  out.wMax = g.wMax;
  out.rgba.clear();
  out.normals.assign(vertexNormals ? size_t(W) * H * kNormalBytes : 0, 0);
  out.covered = 0;
  for (size_t t = 0; t < best.size(); ++t) {
    if (best[t] == -INFINITY) continue;
    out.heights[t] = encodeHeight(best[t], g.wMin, g.wMax);
    ++out.covered;
    if (vertexNormals) {
      // The mesh's vertex normals interpolated over the visible triangle (barycentrics clamped
      // to it past its edges): a smooth field, the same wherever two cells hold the triangle.
      const float* vn = vertexNormals + 9 * size_t(winner[t]);
      double b[3] = {std::max(0.f, bary[2 * t]), std::max(0.f, bary[2 * t + 1]), std::max(0.f, 1 - bary[2 * t] - bary[2 * t + 1])};
      const double sum = b[0] + b[1] + b[2];
      Eigen::Vector3d n = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k) n += b[k] / sum * Eigen::Vector3d(vn[3 * k], vn[3 * k + 1], vn[3 * k + 2]);
      encodeNormal(n.x(), n.y(), n.z(), &out.normals[kNormalBytes * t]);
    }
  }
}

}  // namespace sa
