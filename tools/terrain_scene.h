// The synthetic aerial survey of tools/gen_terrain (rolling terrain, box buildings with roofs
// and walls, RGB, true normals), shared with the tests that need a scene whose normals are known.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

namespace sa::gen {

constexpr double kSize = 1000;                       // metres, square
constexpr double kX0 = 636000, kY0 = 848000, kZ0 = 0;  // georeference (metres)
constexpr double kCell = 50;                           // one building per cell at most

struct Building {
  double x0, y0, x1, y1, top;
};

double ground(double x, double y) {
  return 120 + 18 * std::sin(x / 160) * std::cos(y / 210) + 4 * std::sin(x / 37 + y / 53) + 1.5 * std::cos(x / 11 - y / 17);
}

void groundNormal(double x, double y, float n[3]) {
  const double e = 0.01;
  const double gx = (ground(x + e, y) - ground(x - e, y)) / (2 * e), gy = (ground(x, y + e) - ground(x, y - e)) / (2 * e);
  const double l = std::sqrt(gx * gx + gy * gy + 1);
  n[0] = float(-gx / l), n[1] = float(-gy / l), n[2] = float(1 / l);
}

struct Point {
  double x, y, z;
  float n[3];
  uint16_t rgb[3];
};

struct Scene {
  std::vector<Building> b;
  std::vector<double> wallCum;  // cumulative wall area per building
  double groundArea = kSize * kSize, wallArea = 0;

  Scene() {
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> u(0, 1);
    const int cells = int(kSize / kCell);
    for (int j = 0; j < cells; ++j)
      for (int i = 0; i < cells; ++i) {
        if (u(rng) < 0.55) continue;
        const double w = 10 + 25 * u(rng), h = 10 + 25 * u(rng);
        const double x0 = i * kCell + (kCell - w) * u(rng), y0 = j * kCell + (kCell - h) * u(rng);
        double base = 1e300;
        for (double a : {0.0, 1.0})
          for (double c : {0.0, 1.0}) base = std::min(base, ground(x0 + a * w, y0 + c * h));
        b.push_back({x0, y0, x0 + w, y0 + h, base + 4 + 26 * u(rng) * u(rng)});
      }
    for (const Building& k : b) {
      // Walls from the lowest ground corner up (the part below the ground is never sampled).
      wallArea += 2 * ((k.x1 - k.x0) + (k.y1 - k.y0)) * (k.top - ground(k.x0, k.y0));
      wallCum.push_back(wallArea);
    }
  }

  const Building* roofAt(double x, double y) const {
    const int i = int(x / kCell), j = int(y / kCell);
    for (const Building& k : b)  // few per row: a linear scan over the candidates is enough
      if (int(k.x0 / kCell) == i && int(k.y0 / kCell) == j && x >= k.x0 && x <= k.x1 && y >= k.y0 && y <= k.y1) return &k;
    return nullptr;
  }

  Point sample(std::mt19937_64& rng) const {
    std::uniform_real_distribution<double> u(0, 1);
    std::normal_distribution<double> noise(0, 0.03);
    Point p{};
    if (u(rng) * (groundArea + wallArea) < wallArea) {
      const double a = u(rng) * wallArea;
      size_t k = size_t(std::lower_bound(wallCum.begin(), wallCum.end(), a) - wallCum.begin());
      const Building& w = b[std::min(k, b.size() - 1)];
      const double per = 2 * ((w.x1 - w.x0) + (w.y1 - w.y0));
      double s = u(rng) * per;
      const double lenX = w.x1 - w.x0, lenY = w.y1 - w.y0;
      if (s < lenX) p.x = w.x0 + s, p.y = w.y0, p.n[1] = -1;
      else if ((s -= lenX) < lenY) p.x = w.x1, p.y = w.y0 + s, p.n[0] = 1;
      else if ((s -= lenY) < lenX) p.x = w.x1 - s, p.y = w.y1, p.n[1] = 1;
      else p.x = w.x0, p.y = w.y1 - (s - lenX), p.n[0] = -1;
      const double g = ground(p.x, p.y);
      p.z = g + u(rng) * (w.top - g);
      p.x += noise(rng) * (p.n[0] != 0), p.y += noise(rng) * (p.n[1] != 0);
      p.rgb[0] = 52000, p.rgb[1] = 50000, p.rgb[2] = 46000;  // plaster
      if (p.z < g) p.z = g;
      return p;
    }
    p.x = u(rng) * kSize, p.y = u(rng) * kSize;
    if (const Building* r = roofAt(p.x, p.y)) {
      p.z = r->top + noise(rng);
      p.n[2] = 1;
      p.rgb[0] = 40000, p.rgb[1] = 14000, p.rgb[2] = 12000;  // tiles
      return p;
    }
    p.z = ground(p.x, p.y) + noise(rng);
    groundNormal(p.x, p.y, p.n);
    const double t = std::clamp((p.z - 100) / 45, 0.0, 1.0);
    p.rgb[0] = uint16_t(18000 + 20000 * t), p.rgb[1] = uint16_t(36000 - 6000 * t), p.rgb[2] = uint16_t(12000 + 8000 * t);
    return p;
  }
};

}  // namespace sa::gen
