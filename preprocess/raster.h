// Triangle scan conversion shared by the height-map rasterizer (orthographic, along W, as
// in Lu, Low & Zheng §3.2.1) and reference depth renders (perspective, in tests and eval).
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace sa {

// Calls fn(px, py, b0, b1, b2) for every pixel whose centre (px + 0.5, py + 0.5) lies inside
// the triangle (x[i], y[i]) in pixel units - or, with dilate > 0, within `dilate` pixels of
// it - with barycentric weights (outside the triangle some are negative). Top-left-style
// tie-breaking is not needed here: callers keep the max / min value per pixel.
template <class F>
void rasterizeTriangle(const double x[3], const double y[3], int width, int height, F&& fn, double dilate = 0) {
  const double area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]);
  if (!(std::abs(area) > 1e-300)) return;
  const double minX = std::min({x[0], x[1], x[2]}) - dilate, maxX = std::max({x[0], x[1], x[2]}) + dilate;
  const double minY = std::min({y[0], y[1], y[2]}) - dilate, maxY = std::max({y[0], y[1], y[2]}) + dilate;
  const int x0 = std::max(0, static_cast<int>(std::floor(minX - 0.5)));
  const int x1 = std::min(width - 1, static_cast<int>(std::ceil(maxX - 0.5)));
  const int y0 = std::max(0, static_cast<int>(std::floor(minY - 0.5)));
  const int y1 = std::min(height - 1, static_cast<int>(std::ceil(maxY - 0.5)));
  const double inv = 1.0 / area;
  // Barycentric b_k falls off by |edge k| / |2 area| per pixel away from edge k.
  double slack[3];
  for (int k = 0; k < 3; ++k)
    slack[k] = 1e-9 + dilate * std::hypot(x[(k + 2) % 3] - x[(k + 1) % 3], y[(k + 2) % 3] - y[(k + 1) % 3]) / std::abs(area);
  for (int py = y0; py <= y1; ++py) {
    const double cy = py + 0.5;
    for (int px = x0; px <= x1; ++px) {
      const double cx = px + 0.5;
      const double b0 = ((x[1] - cx) * (y[2] - cy) - (x[2] - cx) * (y[1] - cy)) * inv;
      const double b1 = ((x[2] - cx) * (y[0] - cy) - (x[0] - cx) * (y[2] - cy)) * inv;
      const double b2 = 1.0 - b0 - b1;
      if (b0 < -slack[0] || b1 < -slack[1] || b2 < -slack[2]) continue;
      fn(px, py, b0, b1, b2);
    }
  }
}

}  // namespace sa
