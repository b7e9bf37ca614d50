#include "preprocess/triangle_cells.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>

namespace sa {
namespace {

void grow(CellExtent& c, const Eigen::Vector3d& p) {
  const Eigen::Vector3d d = p - c.origin;
  const double f[3] = {d.dot(c.u), d.dot(c.v), d.dot(c.w)};
  for (int a = 0; a < 3; ++a) {
    c.ext[2 * a] = std::min(c.ext[2 * a], f[a]);
    c.ext[2 * a + 1] = std::max(c.ext[2 * a + 1], f[a]);
  }
}

}  // namespace

Status vertexNormalCones(const std::string& trianglePath, const std::vector<double>& P,
                         const std::vector<float>& vertexNormal, std::vector<float>& cone) {
  std::FILE* f = std::fopen(trianglePath.c_str(), "rb");
  if (!f) return Status::internal(trianglePath + ": cannot reopen");
  cone.assign(P.size() / 3, 0.f);
  std::vector<uint32_t> buf(3 * 65536);
  size_t got;
  while ((got = std::fread(buf.data(), 12, buf.size() / 3, f)) > 0) {
    for (size_t k = 0; k < got; ++k) {
      const uint32_t* v = &buf[3 * k];
      if (3 * size_t(std::max({v[0], v[1], v[2]})) + 2 >= std::min(P.size(), vertexNormal.size())) continue;
      const Eigen::Vector3d a(&P[3 * size_t(v[0])]), b(&P[3 * size_t(v[1])]), c(&P[3 * size_t(v[2])]);
      const Eigen::Vector3d fn = (b - a).cross(c - a);
      if (!(fn.norm() > 0)) continue;
      for (int j = 0; j < 3; ++j) {
        const Eigen::Vector3d n = Eigen::Vector3f(&vertexNormal[3 * size_t(v[j])]).cast<double>();
        if (!(n.norm() > 0)) continue;
        const double angle = std::acos(std::clamp(n.dot(fn) / (n.norm() * fn.norm()), -1.0, 1.0));
        cone[v[j]] = std::max(cone[v[j]], float(angle));
      }
    }
  }
  std::fclose(f);
  return Status::ok();
}

Status assignTrianglesToCells(const TriangleCellInput& in, std::vector<CellExtent>& cells,
                              std::vector<std::pair<uint32_t, uint32_t>>& out) {
  std::FILE* f = std::fopen(in.trianglePath.c_str(), "rb");
  if (!f) return Status::internal(in.trianglePath + ": cannot reopen");
  const std::vector<double>& P = *in.vertexPos;
  const auto& samples = *in.sampleCells;
  auto s = samples.begin();
  std::vector<uint32_t> buf(3 * 65536), cs;
  size_t got;
  uint32_t t = 0;
  while ((got = std::fread(buf.data(), 12, buf.size() / 3, f)) > 0) {
    for (size_t k = 0; k < got; ++k, ++t) {
      const uint32_t* v = &buf[3 * k];
      if (3 * size_t(std::max({v[0], v[1], v[2]})) + 2 >= P.size()) continue;
      const Eigen::Vector3d a(&P[3 * size_t(v[0])]), b(&P[3 * size_t(v[1])]), c(&P[3 * size_t(v[2])]);
      const Eigen::Vector3d fn = (b - a).cross(c - a).normalized();
      auto holds = [&](uint32_t cell) { return cell != UINT32_MAX && fn.dot(cells[cell].w) > in.minCos; };
      while (s != samples.end() && s->first < t) ++s;
      const bool sampled = s != samples.end() && s->first == t;
      cs.clear();
      for (auto q = s; q != samples.end() && q->first == t; ++q) cs.push_back(q->second);
      for (int j = 0; j < 3; ++j) cs.push_back((*in.vertexCell)[v[j]]);
      std::sort(cs.begin(), cs.end());
      cs.erase(std::unique(cs.begin(), cs.end()), cs.end());
      // Each vertex's cell holds the part of the triangle nearer that vertex (the vertex, the
      // midpoints of its two edges and the centroid); the three parts tile the triangle. When
      // a vertex's cell cannot hold it, the cells that can hold it whole.
      const Eigen::Vector3d corner[3] = {a, b, c}, centroid = (a + b + c) / 3;
      bool allHold = true;
      for (int j = 0; j < 3; ++j) allHold = allHold && holds((*in.vertexCell)[v[j]]);
      for (uint32_t cell : cs) {
        if (!holds(cell)) continue;
        if (!sampled) {
          for (int j = 0; j < 3; ++j) {
            if (allHold && (*in.vertexCell)[v[j]] != cell) continue;
            grow(cells[cell], corner[j]);
            grow(cells[cell], (corner[j] + corner[(j + 1) % 3]) / 2);
            grow(cells[cell], (corner[j] + corner[(j + 2) % 3]) / 2);
            grow(cells[cell], allHold ? centroid : corner[(j + 1) % 3]);
          }
        }
        out.emplace_back(t, cell);
      }
    }
  }
  std::fclose(f);
  return Status::ok();
}

}  // namespace sa
