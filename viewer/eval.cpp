#include "viewer/eval.h"

#include <algorithm>
#include <cmath>

namespace sa {

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const size_t k = std::min(v.size() - 1, size_t(q * double(v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + long(k), v.end());
  return v[k];
}

RenderAgreement compareRenders(const std::vector<float>& a, const std::vector<float>& b, double unit) {
  RenderAgreement r;
  std::vector<double> err;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) {
    const bool ha = std::isfinite(a[i]), hb = std::isfinite(b[i]);
    r.onlyA += ha && !hb;
    r.onlyB += hb && !ha;
    if (ha && hb) {
      ++r.both;
      err.push_back(std::abs(double(a[i]) - double(b[i])) / unit);
    }
  }
  const size_t either = r.both + r.onlyA + r.onlyB;
  r.iou = either ? double(r.both) / double(either) : 1.0;
  r.depthMedian = percentile(err, 0.5);
  r.depthP95 = percentile(err, 0.95);
  return r;
}

ViewMetrics evaluateView(const Image& tc, const std::vector<float>& td, const std::vector<float>& tn,
                         const ReferenceView& ref, const Image& rs, double diag) {
  ViewMetrics m;
  const int W = rs.width, H = rs.height;
  size_t perimeter = 0, differ = 0;
  double se = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const size_t i = size_t(y) * W + x;
      const bool a = std::isfinite(td[i]), b = std::isfinite(ref.depth[i]);
      if (b) {
        bool edge = x == 0 || y == 0 || x == W - 1 || y == H - 1;
        if (!edge)
          edge = !std::isfinite(ref.depth[i - 1]) || !std::isfinite(ref.depth[i + 1]) ||
                 !std::isfinite(ref.depth[i - W]) || !std::isfinite(ref.depth[i + W]);
        perimeter += edge;
      }
      if (a != b) ++differ;
      if (a && b) {
        ++m.both;
        m.depthErrors.push_back(std::abs(double(td[i]) - ref.depth[i]) / diag);
        if (!tn.empty()) {
          const double dx = tn[3 * i], dy = tn[3 * i + 1], dz = tn[3 * i + 2];
          const double len = std::sqrt(dx * dx + dy * dy + dz * dz);
          if (len > 0.5) {
            // Reference scan triangles have no consistent winding: compare lines, not signs.
            const double c = std::abs(dx * ref.normals[3 * i] + dy * ref.normals[3 * i + 1] + dz * ref.normals[3 * i + 2]) / len;
            m.normalErrors.push_back(std::acos(std::min(1.0, c)) * 180.0 / M_PI);
          }
        }
      } else if (a) {
        ++m.onlyTest;
      } else if (b) {
        ++m.onlyRef;
        bool inside = x > 0 && y > 0 && x < W - 1 && y < H - 1;
        for (int dy = -1; dy <= 1 && inside; ++dy)
          for (int dx = -1; dx <= 1 && inside; ++dx) inside = std::isfinite(ref.depth[size_t(y + dy) * W + x + dx]);
        m.interiorHoles += inside;
      }
      for (int k = 0; k < 3; ++k) {
        const double d = double(tc.rgba[4 * i + k]) - double(rs.rgba[4 * i + k]);
        se += d * d;
      }
    }
  const size_t uni = m.both + m.onlyTest + m.onlyRef;
  m.iou = uni ? double(m.both) / double(uni) : 1.0;
  m.silhouetteError = perimeter ? double(differ) / double(perimeter) : 0.0;
  m.depthMedian = percentile(m.depthErrors, 0.5);
  m.depthP95 = percentile(m.depthErrors, 0.95);
  m.normalMedianDeg = m.normalErrors.empty() ? -1 : percentile(m.normalErrors, 0.5);
  const double mse = se / (3.0 * W * H);
  m.psnr = mse > 0 ? 10 * std::log10(255.0 * 255.0 / mse) : 99.0;
  return m;
}

std::vector<double> surfacePoints(const Camera& cam, const std::vector<float>& depth, const Eigen::Vector3d& origin) {
  std::vector<double> out;
  const Eigen::Vector3d eye = cam.eye - origin, fwd = cam.forward();
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const float d = depth[size_t(y) * cam.width + x];
      if (!std::isfinite(d)) continue;
      const Eigen::Vector3d dir = cam.rayDirection(x + 0.5, y + 0.5);
      const Eigen::Vector3d p = eye + dir * (double(d) / dir.dot(fwd));
      out.insert(out.end(), {p.x(), p.y(), p.z()});
    }
  return out;
}

SeamStats seamStats(const Camera& cam, const std::vector<float>& depth, const std::vector<float>& normals,
                    const std::vector<uint32_t>& cells) {
  SeamStats st;
  const int W = cam.width, H = cam.height;
  const double footprint = 2 * std::tan(cam.fovDeg * M_PI / 360.0) / H;  // pixel size per unit of depth
  double border = 0, inside = 0;
  auto pair = [&](size_t a, size_t b) {
    if (!cells[a] || !cells[b] || !std::isfinite(depth[a]) || !std::isfinite(depth[b])) return;
    if (std::abs(double(depth[a]) - depth[b]) > 6 * footprint * std::min(depth[a], depth[b])) return;
    const Eigen::Vector3d na(normals[3 * a], normals[3 * a + 1], normals[3 * a + 2]);
    const Eigen::Vector3d nb(normals[3 * b], normals[3 * b + 1], normals[3 * b + 2]);
    if (!(na.norm() > 0.5 && nb.norm() > 0.5)) return;
    const double deg = std::acos(std::clamp(na.normalized().dot(nb.normalized()), -1.0, 1.0)) * 180 / M_PI;
    if (cells[a] != cells[b]) {
      border += deg;
      ++st.borderPairs;
    } else {
      inside += deg;
      ++st.insidePairs;
    }
  };
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const size_t i = size_t(y) * W + x;
      if (x + 1 < W) pair(i, i + 1);
      if (y + 1 < H) pair(i, i + W);
    }
  st.borderMeanDeg = st.borderPairs ? border / double(st.borderPairs) : 0;
  st.insideMeanDeg = st.insidePairs ? inside / double(st.insidePairs) : 0;
  return st;
}

}  // namespace sa
