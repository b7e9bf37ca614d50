#include "grooves/raster.h"

#include <algorithm>
#include <cmath>

namespace sa::grooves {
namespace {

// One box pass of radius r along rows (dx = 1) or columns, zero outside.
void boxPass(const Img& in, Img& out, int r, bool rows) {
  const int n = rows ? in.w : in.h, lines = rows ? in.h : in.w;
  out = Img(in.w, in.h);
  std::vector<double> line(size_t(n) + 1);
  for (int l = 0; l < lines; ++l) {
    line[0] = 0;
    for (int i = 0; i < n; ++i) line[i + 1] = line[i] + (rows ? in.at(i, l) : in.at(l, i));
    for (int i = 0; i < n; ++i) {
      const int a = std::max(0, i - r), b = std::min(n, i + r + 1);
      const float s = float(line[b] - line[a]);
      (rows ? out.at(i, l) : out.at(l, i)) = s;
    }
  }
}

Img boxBlur3(const Img& in, int r) {
  Img a = in, b;
  for (int k = 0; k < 3; ++k) {
    boxPass(a, b, r, true);
    boxPass(b, a, r, false);
  }
  return a;
}

// Correlation along rows or columns with kernel k (centre at index R), zero outside.
Img convolve(const Img& in, const std::vector<float>& k, bool rows) {
  const int R = int(k.size() / 2);
  Img out(in.w, in.h);
  for (int y = 0; y < in.h; ++y)
    for (int x = 0; x < in.w; ++x) {
      float s = 0;
      for (int j = -R; j <= R; ++j) {
        const int xx = rows ? x + j : x, yy = rows ? y : y + j;
        if (xx < 0 || yy < 0 || xx >= in.w || yy >= in.h) continue;
        s += in.at(xx, yy) * k[j + R];
      }
      out.at(x, y) = s;
    }
  return out;
}

}  // namespace

float Img::bilinear(double x, double y) const {
  x = std::clamp(x, 0.0, double(w - 1));
  y = std::clamp(y, 0.0, double(h - 1));
  const int x0 = std::min(int(x), w - 2 < 0 ? 0 : w - 2), y0 = std::min(int(y), h - 2 < 0 ? 0 : h - 2);
  const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
  const double fx = x - x0, fy = y - y0;
  return float((1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x1, y0)) + fy * ((1 - fx) * at(x0, y1) + fx * at(x1, y1)));
}

Img maskedLowPass(const Img& value, const Img& mask, double sigma) {
  // Three box passes of width b approximate a Gaussian of variance 3 (b^2 - 1) / 12.
  const int r = std::max(1, int(std::lround((std::sqrt(4 * sigma * sigma + 1) - 1) / 2)));
  Img num(value.w, value.h);
  for (size_t i = 0; i < num.a.size(); ++i) num.a[i] = value.a[i] * mask.a[i];
  const Img n = boxBlur3(num, r), d = boxBlur3(mask, r);
  Img out(value.w, value.h);
  for (size_t i = 0; i < out.a.size(); ++i) out.a[i] = d.a[i] > 1e-6f ? n.a[i] / d.a[i] : 0.f;
  return out;
}

Derivatives gaussianDerivatives(const Img& in, double sigma) {
  const int R = std::max(2, int(std::ceil(3.5 * sigma)));
  std::vector<float> g(2 * R + 1), g1(2 * R + 1), g2(2 * R + 1);
  double sg = 0, s1 = 0, s2 = 0, m2 = 0;
  for (int k = -R; k <= R; ++k) sg += std::exp(-k * k / (2 * sigma * sigma));
  for (int k = -R; k <= R; ++k) {
    const double e = std::exp(-k * k / (2 * sigma * sigma)) / sg;
    g[k + R] = float(e);
    g1[k + R] = float(k * e);
    s1 += k * k * e;
    g2[k + R] = float((k * k / (sigma * sigma) - 1) * e);
    m2 += g2[k + R];
  }
  // First derivative: exact on a linear ramp. Second: zero sum, exact on k^2 / 2.
  for (float& v : g1) v = float(v / s1);
  for (int k = -R; k <= R; ++k) {
    g2[k + R] = float(g2[k + R] - m2 / (2 * R + 1));
    s2 += 0.5 * k * k * g2[k + R];
  }
  for (float& v : g2) v = float(v / s2);
  const Img r0 = convolve(in, g, true), r1 = convolve(in, g1, true), r2 = convolve(in, g2, true);
  Derivatives d;
  d.x = convolve(r1, g, false);
  d.y = convolve(r0, g1, false);
  d.xx = convolve(r2, g, false);
  d.xy = convolve(r1, g1, false);
  d.yy = convolve(r0, g2, false);
  return d;
}

float median(std::vector<float>& v) {
  if (v.empty()) return 0;
  auto mid = v.begin() + v.size() / 2;
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

}  // namespace sa::grooves
