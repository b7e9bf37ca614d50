#include "preprocess/pullpush.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "atlas/pack_format.h"
#include "preprocess/raster.h"

namespace sa {
namespace {

struct Level {
  int w = 0, h = 0;
  std::vector<float> weight;   // clamped to [0, 1] after the pull
  std::vector<double> value;   // height
  std::vector<float> color;    // rgb, when present
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

}  // namespace

void pullPushTile(const TileGrid& g, const double* u, const double* v, const double* w, const uint8_t* rgb,
                  size_t n, double coverageRadius, TileOutput& out) {
  const int W = g.width, H = g.height;
  const bool hasColor = rgb != nullptr;
  std::vector<Level> lv(1);
  lv[0].w = W; lv[0].h = H;
  lv[0].weight.assign(size_t(W) * H, 0.f);
  lv[0].value.assign(size_t(W) * H, 0.0);
  if (hasColor) lv[0].color.assign(size_t(W) * H * 3, 0.f);
  std::vector<uint8_t> covered(size_t(W) * H, 0);
  const Quadric trend = fitQuadric(g, u, v, w, n);
  const double ru = coverageRadius / g.du, rv = coverageRadius / g.dv;
  const int riv = static_cast<int>(std::ceil(rv));
  // Coverage disks are stamped row by row: one square root per row, then a fill.
  // Splat: bilinear weights onto the four nearest texel centres (the finest level).
  for (size_t s = 0; s < n; ++s) {
    const double fx = (u[s] - g.u0) / g.du - 0.5, fy = (v[s] - g.v0) / g.dv - 0.5;
    if (!(fx > -1.0 && fy > -1.0 && fx < W && fy < H)) continue;
    const int ix = static_cast<int>(std::floor(fx)), iy = static_cast<int>(std::floor(fy));
    const double ax = fx - ix, ay = fy - iy;
    for (int dy = 0; dy < 2; ++dy) {
      for (int dx = 0; dx < 2; ++dx) {
        const int x = ix + dx, y = iy + dy;
        if (x < 0 || y < 0 || x >= W || y >= H) continue;
        const double wt = (dx ? ax : 1 - ax) * (dy ? ay : 1 - ay);
        if (wt <= 0) continue;
        const size_t t = size_t(y) * W + x;
        lv[0].weight[t] += float(wt);
        lv[0].value[t] += wt * (w[s] - trend(u[s], v[s]));
        if (hasColor)
          for (int c = 0; c < 3; ++c) lv[0].color[3 * t + c] += float(wt * rgb[3 * s + c]);
      }
    }
    // Coverage: every texel centre within the radius of this sample.
    const int cy = static_cast<int>(std::lround(fy));
    for (int y = std::max(0, cy - riv - 1); y <= std::min(H - 1, cy + riv + 1); ++y) {
      const double dy = (y - fy) / rv;
      const double span = 1.0 - dy * dy;
      if (span < 0) continue;
      const double half = std::sqrt(span) * ru;  // the disk's half-width on this row
      const int x0 = std::max(0, static_cast<int>(std::ceil(fx - half)));
      const int x1 = std::min(W - 1, static_cast<int>(std::floor(fx + half)));
      if (x0 <= x1) std::fill(covered.begin() + (size_t(y) * W + x0), covered.begin() + (size_t(y) * W + x1 + 1), 1);
    }
  }
  auto normalize = [&](Level& L) {
    for (size_t t = 0; t < L.weight.size(); ++t) {
      if (L.weight[t] > 0) {
        L.value[t] /= L.weight[t];
        if (hasColor)
          for (int c = 0; c < 3; ++c) L.color[3 * t + c] /= L.weight[t];
        L.weight[t] = std::min(L.weight[t], 1.f);
      }
    }
  };
  normalize(lv[0]);
  // Pull: average 2x2 children with their weights into coarser levels.
  while (lv.back().w > 1 || lv.back().h > 1) {
    const Level& f = lv.back();
    Level c;
    c.w = (f.w + 1) / 2;
    c.h = (f.h + 1) / 2;
    c.weight.assign(size_t(c.w) * c.h, 0.f);
    c.value.assign(size_t(c.w) * c.h, 0.0);
    if (hasColor) c.color.assign(size_t(c.w) * c.h * 3, 0.f);
    for (int y = 0; y < f.h; ++y) {
      for (int x = 0; x < f.w; ++x) {
        const size_t ft = size_t(y) * f.w + x, ct = size_t(y / 2) * c.w + x / 2;
        const float wt = f.weight[ft];
        if (wt <= 0) continue;
        c.weight[ct] += wt;
        c.value[ct] += wt * f.value[ft];
        if (hasColor)
          for (int k = 0; k < 3; ++k) c.color[3 * ct + k] += wt * f.color[3 * ft + k];
      }
    }
    normalize(c);
    lv.push_back(std::move(c));
  }
  // Push: fill each level's weak texels from the coarser level (bilinear).
  for (int l = static_cast<int>(lv.size()) - 2; l >= 0; --l) {
    Level& f = lv[size_t(l)];
    const Level& c = lv[size_t(l) + 1];
    for (int y = 0; y < f.h; ++y) {
      for (int x = 0; x < f.w; ++x) {
        const size_t ft = size_t(y) * f.w + x;
        const float wt = f.weight[ft];
        if (wt >= 1.f) continue;
        // Position of this texel centre in the coarse grid.
        const double cx = std::clamp((x + 0.5) / 2.0 - 0.5, 0.0, double(c.w - 1));
        const double cy = std::clamp((y + 0.5) / 2.0 - 0.5, 0.0, double(c.h - 1));
        const int x0 = static_cast<int>(cx), y0 = static_cast<int>(cy);
        const int x1 = std::min(x0 + 1, c.w - 1), y1 = std::min(y0 + 1, c.h - 1);
        const double ax = cx - x0, ay = cy - y0;
        double val = 0, col[3] = {0, 0, 0}, ws = 0;
        const int xs[2] = {x0, x1}, ys[2] = {y0, y1};
        for (int j = 0; j < 2; ++j) {
          for (int i = 0; i < 2; ++i) {
            const size_t ct = size_t(ys[j]) * c.w + xs[i];
            const double bw = (i ? ax : 1 - ax) * (j ? ay : 1 - ay) * c.weight[ct];
            ws += bw;
            val += bw * c.value[ct];
            if (hasColor)
              for (int k = 0; k < 3; ++k) col[k] += bw * c.color[3 * ct + k];
          }
        }
        if (ws <= 0) continue;
        f.value[ft] = wt * f.value[ft] + (1 - wt) * val / ws;
        if (hasColor)
          for (int k = 0; k < 3; ++k) f.color[3 * ft + k] = float(wt * f.color[3 * ft + k] + (1 - wt) * col[k] / ws);
        f.weight[ft] = 1.f;
      }
    }
  }
  out.heights.assign(size_t(W) * H, 0);
  out.rgba.assign(hasColor ? size_t(W) * H * 4 : 0, 0);
  out.covered = 0;
  const Level& L = lv[0];
  for (size_t t = 0; t < out.heights.size(); ++t) {
    if (!covered[t] || L.weight[t] <= 0) continue;
    const int i = static_cast<int>(t % size_t(W)), j = static_cast<int>(t / size_t(W));
    out.heights[t] = encodeHeight(L.value[t] + trend(g.u0 + (i + 0.5) * g.du, g.v0 + (j + 0.5) * g.dv), g.wMin, g.wMax);
    ++out.covered;
    if (hasColor) {
      for (int k = 0; k < 3; ++k)
        out.rgba[4 * t + k] = static_cast<uint8_t>(std::clamp(std::lround(L.color[3 * t + k]), 0L, 255L));
      out.rgba[4 * t + 3] = 255;
    }
  }
}

void rasterizeTile(const TileGrid& g, const double* tris, size_t triangleCount, double slack, TileOutput& out) {
  const int W = g.width, H = g.height;
  std::vector<double> best(size_t(W) * H, -INFINITY);
  for (size_t t = 0; t < triangleCount; ++t) {
    const double* p = tris + 9 * t;
    double x[3], y[3], z[3];
    for (int k = 0; k < 3; ++k) {
      x[k] = (p[3 * k] - g.u0) / g.du;
      y[k] = (p[3 * k + 1] - g.v0) / g.dv;
      z[k] = p[3 * k + 2];
    }
    rasterizeTriangle(x, y, W, H, [&](int px, int py, double b0, double b1, double b2) {
      const double wz = b0 * z[0] + b1 * z[1] + b2 * z[2];
      if (wz < g.wMin - slack || wz > g.wMax + slack) return;
      double& d = best[size_t(py) * W + px];
      d = std::max(d, wz);
    });
  }
  out.heights.assign(size_t(W) * H, 0);
  out.rgba.clear();
  out.covered = 0;
  for (size_t t = 0; t < best.size(); ++t) {
    if (best[t] == -INFINITY) continue;
    out.heights[t] = encodeHeight(best[t], g.wMin, g.wMax);
    ++out.covered;
  }
}

}  // namespace sa
