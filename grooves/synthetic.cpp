// Synthetic groove scans for the detection tests and `sa_gen_grooves`.
#include <algorithm>
#include <cmath>
#include <random>

#include <Eigen/Geometry>

#include "grooves/grooves.h"

namespace sa {
namespace {

// A groove's centre line from a few control points (straight) or a sampled curve.
SyntheticGroove straight(double x0, double y0, double x1, double y1, double w, double d, bool u) {
  SyntheticGroove g;
  g.line = {Eigen::Vector2d(x0, y0), Eigen::Vector2d(x1, y1)};
  g.width = w;
  g.depth = d;
  g.rounded = u;
  return g;
}

template <class F>
SyntheticGroove curve(F f, int steps, double w, double d, bool u) {
  SyntheticGroove g;
  for (int i = 0; i <= steps; ++i) g.line.push_back(f(double(i) / steps));
  g.width = w;
  g.depth = d;
  g.rounded = u;
  return g;
}

double segmentDistance(const Eigen::Vector2d& p, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const Eigen::Vector2d ab = b - a;
  const double t = std::clamp((p - a).dot(ab) / std::max(ab.squaredNorm(), 1e-300), 0.0, 1.0);
  return (a + t * ab - p).norm();
}

double lineDistance(const Eigen::Vector2d& p, const SyntheticGroove& g) {
  double best = 1e300;
  for (size_t i = 0; i + 1 < g.line.size(); ++i) best = std::min(best, segmentDistance(p, g.line[i], g.line[i + 1]));
  return best;
}

// Depth of the cut at distance r from the centre line (0 outside).
double cut(const SyntheticGroove& g, double r) {
  const double x = r / (g.width / 2);
  if (x >= 1) return 0;
  return g.rounded ? g.depth * std::sqrt(1 - x * x) : g.depth * (1 - x);
}

// The ten grooves, in spacings on a 400 x 400 plane (scaled to the scan's size), widths in
// spacings and depths in noise units.
std::vector<SyntheticGroove> tenGrooves() {
  std::vector<SyntheticGroove> g;
  g.push_back(straight(30, 50, 370, 70, 6, 20, false));    // long, wide, deep
  g.push_back(straight(30, 350, 370, 330, 4, 10, true));   // U
  g.push_back(straight(360, 110, 350, 300, 3, 5, false));  // at the detection limit
  g.push_back(curve([](double t) { const double a = M_PI * (0.2 + 0.7 * t);
                      return Eigen::Vector2d(200 + 80 * std::cos(a), 200 + 80 * std::sin(a)); }, 64, 3, 8, false));
  g.push_back(curve([](double t) { const double x = 180 + 150 * t;
                      return Eigen::Vector2d(x, 130 + 12 * std::sin(2 * M_PI * (x - 180) / 100)); }, 64, 5, 6, true));
  g.push_back(straight(120, 20, 140, 180, 4, 12, false));  // crosses the first
  g.push_back(straight(60, 160, 100, 260, 3, 15, true));   // both ends inside
  g.push_back(straight(170, 175, 320, 190, 1.5, 10, false));  // narrower than the test's bound
  g.push_back(straight(20, 290, 110, 310, 6, 3, true));    // shallower than the test's bound
  g.push_back(curve([](double t) { const double s = 1 - t;  // crosses the U groove, ends inside
                      return Eigen::Vector2d(s * s * 250 + 2 * s * t * 320 + t * t * 280,
                                             s * s * 270 + 2 * s * t * 320 + t * t * 385); }, 48, 3.5, 7, false));
  return g;
}

}  // namespace

double GrooveSet::totalLength() const {
  double s = 0;
  for (const Groove& g : grooves) s += g.length;
  return s;
}

Eigen::Vector3d SyntheticScan::toWorld(const Eigen::Vector2d& p) const {
  return origin + frame.col(0) * p.x() + frame.col(1) * p.y() + frame.col(2) * baseHeight(p);
}

double SyntheticScan::baseHeight(const Eigen::Vector2d& p) const {
  return 4 * spacing * std::sin(2 * M_PI * p.x() / (300 * spacing)) * std::cos(2 * M_PI * p.y() / (370 * spacing));
}

std::vector<SyntheticGroove> acceptanceGrooves(double size, double spacing, double noise) {
  std::vector<SyntheticGroove> out;
  const double k = size / (400 * spacing);
  for (SyntheticGroove g : tenGrooves()) {
    for (Eigen::Vector2d& p : g.line) p *= k * spacing;
    g.width *= spacing;
    g.depth *= noise;
    out.push_back(g);
  }
  return out;
}

SyntheticScan makeGrooveScan(double size, double spacing, double noise, const std::vector<SyntheticGroove>& grooves,
                             uint32_t seed) {
  SyntheticScan s;
  s.spacing = spacing;
  s.noise = noise;
  s.size = size;
  s.frame = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  s.origin = Eigen::Vector3d(100, 50, 20) * spacing;
  s.grooves = grooves;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(0, 1);
  std::normal_distribution<double> gauss(0, noise);
  const int n = int(std::floor(size / spacing));
  s.pos.reserve(size_t(3) * n * n);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector2d p((i + jitter(rng)) * spacing, (j + jitter(rng)) * spacing);
      double h = 0;
      bool removed = false;
      for (const SyntheticGroove& g : s.grooves) {
        const double r = lineDistance(p, g);
        if (r >= g.width / 2) continue;
        if (g.uncovered) removed = true;
        h = std::min(h, -cut(g, r));
      }
      const double e = gauss(rng);
      if (removed) continue;
      const Eigen::Vector3d w = s.toWorld(p) + s.frame.col(2) * (h + e);
      s.pos.insert(s.pos.end(), {w.x(), w.y(), w.z()});
    }
  }
  return s;
}

}  // namespace sa
