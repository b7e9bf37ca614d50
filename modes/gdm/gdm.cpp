#include "modes/gdm/gdm.h"

#include <tbb/parallel_for.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <mutex>
#include <random>
#include <sstream>
#include <unordered_map>

#include "formats/source.h"
#include "common/ray_box.h"
#include "modes/pack_sources.h"
#include "preprocess/normals.h"

namespace sa::gdm {
namespace {

Eigen::Vector3d gridMin(const CellRecord& c) { return {c.box[0], c.box[2], c.box[4]}; }

// The field inside voxel (x, y, z): its eight corners (frame units), trilinear.
struct VoxelField {
  double f[8];
  Eigen::Vector3d lo, vs;
  VoxelField(const CellGrid& g, int x, int y, int z, const Eigen::Vector3d& gridLo) {
    vs = Eigen::Vector3d(g.vx, g.vy, g.vz);
    lo = gridLo + Eigen::Vector3d(x, y, z).cwiseProduct(vs);
    for (int k = 0; k < 8; ++k) f[k] = g.unit() * g.corners[g.cornerIndex(x + (k & 1), y + ((k >> 1) & 1), z + (k >> 2))];
  }
  double at(const Eigen::Vector3d& q) const {
    const Eigen::Vector3d s = (q - lo).cwiseQuotient(vs);
    const double x0 = f[0] + (f[1] - f[0]) * s.x(), x1 = f[2] + (f[3] - f[2]) * s.x();
    const double x2 = f[4] + (f[5] - f[4]) * s.x(), x3 = f[6] + (f[7] - f[6]) * s.x();
    const double y0 = x0 + (x1 - x0) * s.y(), y1 = x2 + (x3 - x2) * s.y();
    return y0 + (y1 - y0) * s.z();
  }
  Eigen::Vector3d gradient(const Eigen::Vector3d& q) const {
    const Eigen::Vector3d s = (q - lo).cwiseQuotient(vs);
    auto lerp = [](double a, double b, double t) { return a + (b - a) * t; };
    const double gx = lerp(lerp(f[1] - f[0], f[3] - f[2], s.y()), lerp(f[5] - f[4], f[7] - f[6], s.y()), s.z());
    const double gy = lerp(lerp(f[2] - f[0], f[3] - f[1], s.x()), lerp(f[6] - f[4], f[7] - f[5], s.x()), s.z());
    const double gz = lerp(lerp(f[4] - f[0], f[5] - f[1], s.x()), lerp(f[6] - f[2], f[7] - f[3], s.x()), s.y());
    return Eigen::Vector3d(gx, gy, gz).cwiseQuotient(vs);
  }
};

}  // namespace

int16_t quantizeCorner(const CellGrid& g, double f) {
  return int16_t(std::lround(std::clamp(f / g.unit(), -32767.0, 32767.0)));
}

void finishStates(CellGrid& g) {
  g.state.assign(g.voxelCount(), kVoxelUnknown);
  for (int z = 0; z < g.nz; ++z)
    for (int y = 0; y < g.ny; ++y)
      for (int x = 0; x < g.nx; ++x) {
        bool known = true, under = false;
        for (int k = 0; k < 8 && known; ++k) {
          const int16_t v = g.corners[g.cornerIndex(x + (k & 1), y + ((k >> 1) & 1), z + (k >> 2))];
          known = v != kUnknown;
          under = under || v <= 0;
        }
        g.state[(size_t(z) * g.ny + y) * g.nx + x] = !known ? kVoxelUnknown : under ? kVoxelOccupied : kVoxelOutside;
      }
}

namespace {

// One corner's weighted sums over its samples, positions relative to the corner.
struct SphereSums {
  float w = 0, pn = 0, pp = 0;
  Eigen::Vector3f p = Eigen::Vector3f::Zero(), n = Eigen::Vector3f::Zero();
};

// Signed distance from the corner (the origin of the sums) to the algebraic sphere fitted to its
// samples with their normals (Guennebaud & Gross 2007, APSS: s(x) = u0 + u123.x + u4 |x|^2,
// positive where the normals point). The implicit MLS field (each sample's tangent plane, sphere
// false) bulges out of a convex surface by about h^2 / 2R for a kernel h and a radius R: on the
// bunny's forced cells, at the 2-3 spacing kernel its merged scans need, its surface lay a median
// 0.27 spacing in front of the height field's. The sphere follows the curvature. Triangles'
// samples keep the tangent planes: they are exact, their kernel half a
// voxel makes the bias a hundredth of a voxel, and a sphere fitted across a mesh's sharp crease
// bulges past it (the synthetic mushroom's rim: IoU 0.989 with the plane, 0.974 with spheres).
// The distance along the gradient, 2 u0 / (|u123| + sqrt(|u123|^2 - 4 u0 u4)), is
// |c| - r written without cancelling, and the plane's u0 / |u123| where u4 is 0.
double sphereDistance(const SphereSums& a, bool sphere) {
  const double W = a.w;
  if (!sphere) return -double(a.pn) / W;  // the implicit MLS field, sum w (x - p) . n / sum w
  const Eigen::Vector3d P = a.p.cast<double>() / W, N = a.n.cast<double>() / W;
  const double spread = double(a.pp) / W - P.squaredNorm();
  const double u4 = spread > 1e-12 * double(a.pp) / W ? 0.5 * (double(a.pn) / W - P.dot(N)) / spread : 0.0;
  const Eigen::Vector3d u123 = N - 2 * u4 * P;
  const double u0 = -u123.dot(P) - u4 * double(a.pp) / W;
  const double g = u123.norm(), disc = g * g - 4 * u0 * u4;
  if (!(g > 0)) return 0;
  return disc > 0 ? 2 * u0 / (g + std::sqrt(disc)) : u0 / g;
}

// Sets g.corners and g.state: the samples' algebraic sphere distance with a Gaussian kernel
// (sphereDistance), known within band of a sample. Two passes over the samples: each corner's
// nearest sample (its side of a thin part), then the weighted sums of the samples facing that
// side (n . n_nearest > 0), so however wide the kernel, the two sides of a part thinner than it
// never average into one.
void fillField(CellGrid& g, const CellRecord& c, const Samples& s, double kernel, double band, bool sphere) {
  const Eigen::Vector3d vs(g.vx, g.vy, g.vz), lo = gridMin(c);
  const double reach = std::max(2.5 * kernel, band), inv2 = 1.0 / (kernel * kernel);
  const int N[3] = {g.nx, g.ny, g.nz};
  const size_t corners = size_t(g.nx + 1) * (g.ny + 1) * (g.nz + 1);
  std::vector<float> near2(corners, INFINITY);
  std::vector<SphereSums> sums(corners);
  std::vector<Eigen::Vector3f> nearN(corners, Eigen::Vector3f::Zero());
  for (int pass = 0; pass < 2; ++pass)
    for (size_t i = 0; i < s.p.size(); ++i) {
      if (!(s.n[i].squaredNorm() > 0)) continue;
      const Eigen::Vector3d n = s.n[i].normalized();
      const Eigen::Vector3d& p = s.p[i];
      int a0[3], a1[3];
      for (int k = 0; k < 3; ++k) {
        a0[k] = std::clamp(int(std::ceil((p[k] - reach - lo[k]) / vs[k])), 0, N[k]);
        a1[k] = std::clamp(int(std::floor((p[k] + reach - lo[k]) / vs[k])), 0, N[k]);
      }
      for (int z = a0[2]; z <= a1[2]; ++z)
        for (int y = a0[1]; y <= a1[1]; ++y)
          for (int x = a0[0]; x <= a1[0]; ++x) {
            const Eigen::Vector3d r = p - (lo + Eigen::Vector3d(x, y, z).cwiseProduct(vs));  // sample - corner
            const double d2 = r.squaredNorm();
            if (d2 > reach * reach) continue;
            const size_t ci = g.cornerIndex(x, y, z);
            if (pass == 0) {
              if (float(d2) < near2[ci]) {
                near2[ci] = float(d2);
                nearN[ci] = n.cast<float>();
              }
            } else if (nearN[ci].cast<double>().dot(n) > 0) {
              const double w = std::exp(-d2 * inv2);
              SphereSums& a = sums[ci];
              a.w += float(w);
              a.p += (w * r).cast<float>();
              a.n += (w * n).cast<float>();
              a.pn += float(w * r.dot(n));
              a.pp += float(w * d2);
            }
          }
    }
  g.corners.assign(corners, kUnknown);
  for (size_t ci = 0; ci < corners; ++ci)
    if (near2[ci] <= band * band && sums[ci].w > 0) g.corners[ci] = quantizeCorner(g, sphereDistance(sums[ci], sphere));
  finishStates(g);
}

// The field's trilinear value at q (frame) where its voxel is known, else NaN.
double fieldAt(const CellGrid& g, const CellRecord& c, const Eigen::Vector3d& q) {
  const Eigen::Vector3d lo = gridMin(c), f = (q - lo).cwiseQuotient(Eigen::Vector3d(g.vx, g.vy, g.vz));
  const int x = int(std::floor(f.x())), y = int(std::floor(f.y())), z = int(std::floor(f.z()));
  if (x < 0 || y < 0 || z < 0 || x >= g.nx || y >= g.ny || z >= g.nz || g.at(x, y, z) == kVoxelUnknown) return NAN;
  return VoxelField(g, x, y, z, lo).at(q);
}

// The samples' noise about the field: 1.4826 x the median of |f| at the samples (a robust sigma).
double sampleNoise(const CellGrid& g, const CellRecord& c, const Samples& s) {
  std::vector<double> r;
  for (size_t i = 0; i < s.p.size(); ++i) {
    const double f = fieldAt(g, c, s.p[i]);
    if (s.n[i].squaredNorm() > 0 && std::isfinite(f)) r.push_back(std::abs(f));
  }
  if (r.empty()) return 0;
  std::nth_element(r.begin(), r.begin() + r.size() / 2, r.end());
  return 1.4826 * r[r.size() / 2];
}

}  // namespace

CellGrid buildGrid(const CellRecord& c, uint32_t cell, const Samples& s, double spacing) {
  CellGrid g;
  g.cell = cell;
  g.nx = c.tileW;
  g.ny = c.tileH;
  g.vx = (c.box[1] - c.box[0]) / g.nx;
  g.vy = (c.box[3] - c.box[2]) / g.ny;
  const double h = c.box[5] - c.box[4];
  g.vz = std::max(std::min(g.vx, g.vy), 1e-300);
  g.nz = h > 0 ? std::clamp(int(std::ceil(h / g.vz)), 1, 1024) : 1;
  if (h > 0) g.vz = h / g.nz;
  if (!(g.vx > 0 && g.vy > 0) || uint64_t(g.nx + 1) * (g.ny + 1) * (g.nz + 1) > (uint64_t(1) << 22)) {
    g.nx = g.ny = g.nz = 0;  // degenerate or too large: the cell draws its fallback
    return g;
  }
  // The band: corners within it of a sample are known, so every voxel the surface passes (within
  // half a spacing of a sample) has its eight corners known. Triangles' samples lie half a voxel
  // apart: their kernel is that step.
  const double diag = Eigen::Vector3d(g.vx, g.vy, g.vz).norm(), step = 0.5 * std::min(g.vx, g.vy);
  if (spacing <= 0) {
    fillField(g, c, s, step, diag + 0.5 * step, false);
    return g;
  }
  const double band = std::max(1.5 * spacing, diag + 0.5 * spacing);
  fillField(g, c, s, spacing, band, true);
  // A kernel of width h averages about pi h^2 / s^2 samples, so the field keeps sigma s / (sqrt(pi) h)
  // of the samples' noise sigma: noisy samples (merged scans that disagree) widen it until that is a
  // kFieldNoise (2 %) of a spacing, up to 3 spacings (measured: the bunny's raw scans' forced cells 0.13-0.25
  // spacings, clean synthetic points 0.01-0.07 about their spheres, which keep one spacing). With
  // the plane fit it was 3 %: wider bulged the bunny's ears; the sphere keeps their size.
  const double noise = sampleNoise(g, c, s);
  const double widen = std::clamp(noise / (std::sqrt(M_PI) * kFieldNoise * spacing), 1.0, kMaxKernel);
  g.kernel = widen > 1.05 ? widen : 1.0;
  if (widen > 1.05) fillField(g, c, s, widen * spacing, band, true);
  return g;
}

namespace {

// The first crossing of the voxel's zero set along o + t d over [ta, tb], either way (a camera
// inside a thin part sees its walls): kCrossSamples even steps find the first interval whose ends
// differ in sign (the value along a ray is a cubic), then bisection and a final secant step
// (gdm_voxels.glsl takes the same steps in float).
inline constexpr int kCrossSamples = 4, kCrossBisections = 10;
bool crossing(const VoxelField& v, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double ta, double tb, double& tHit) {
  double fa = v.at(o + d * ta), a = ta;
  for (int i = 1; i <= kCrossSamples; ++i) {
    double b = ta + (tb - ta) * i / kCrossSamples, fb = v.at(o + d * b);
    if ((fa > 0) != (fb > 0)) {
      for (int k = 0; k < kCrossBisections; ++k) {
        const double m = 0.5 * (a + b), fm = v.at(o + d * m);
        if ((fm > 0) == (fa > 0)) {
          a = m;
          fa = fm;
        } else {
          b = m;
          fb = fm;
        }
      }
      tHit = a + (b - a) * fa / (fa - fb);
      return true;
    }
    a = b;
    fa = fb;
  }
  return false;
}

// The DDA from t0 (first voxel: where o + t0 d lies) to t1; n: the voxels visited. A crossing
// counts from tAccept on (the first voxel: from where the ray enters it, so a walk that starts
// inside a voxel, the guided one, finds what a walk from the box would). touched: a known voxel
// was passed.
bool walk(const CellRecord& c, const CellGrid& g, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t0, double t1,
          double tAccept, double& tHit, Eigen::Vector3d* normal, uint32_t& n, bool& touched) {
  const Eigen::Vector3d vs(g.vx, g.vy, g.vz), lo = gridMin(c);
  const int N[3] = {g.nx, g.ny, g.nz};
  const Eigen::Vector3d p = o + d * t0 - lo;
  int idx[3], step[3];
  double tMax[3], tDelta[3];
  double t = t0;
  double entry = -INFINITY;  // where the ray entered this voxel
  for (int k = 0; k < 3; ++k) {
    idx[k] = std::clamp(int(std::floor(p[k] / vs[k])), 0, N[k] - 1);
    step[k] = d[k] > 0 ? 1 : (d[k] < 0 ? -1 : 0);
    tDelta[k] = d[k] != 0 ? vs[k] / std::abs(d[k]) : INFINITY;
    tMax[k] = d[k] != 0 ? t0 + ((idx[k] + (step[k] > 0 ? 1 : 0)) * vs[k] - p[k]) / d[k] : INFINITY;
    if (d[k] != 0) entry = std::max(entry, tMax[k] - tDelta[k]);
  }
  t = std::max(std::min(entry, t), tAccept);
  const uint32_t cap = uint32_t(g.nx + g.ny + g.nz + 4);
  for (n = 0; n < cap; ++n) {
    const int a = tMax[0] <= tMax[1] ? (tMax[0] <= tMax[2] ? 0 : 2) : (tMax[1] <= tMax[2] ? 1 : 2);
    const double tNext = std::min(std::max(tMax[a], t), t1);
    const uint8_t st = g.at(idx[0], idx[1], idx[2]);
    touched = touched || st != kVoxelUnknown;
    if (st == kVoxelOccupied) {
      const VoxelField v(g, idx[0], idx[1], idx[2], lo);
      if (crossing(v, o, d, t, tNext, tHit)) {
        if (normal) {
          const Eigen::Vector3d gr = v.gradient(o + d * tHit);
          *normal = gr.squaredNorm() > 0 ? Eigen::Vector3d(gr.normalized() * (gr.dot(d) > 0 ? -1.0 : 1.0))
                                         : Eigen::Vector3d(-d.normalized());
        }
        ++n;
        return true;
      }
    }
    if (tNext >= t1) {
      ++n;
      return false;
    }
    idx[a] += step[a];
    if (idx[a] < 0 || idx[a] >= N[a]) {
      ++n;
      return false;
    }
    t = tNext;
    tMax[a] += tDelta[a];
  }
  return false;
}

int thetaBin(const Eigen::Vector3d& d) {
  const double z = std::clamp(d.z() / d.norm(), -1.0, 1.0);
  return std::clamp(int(std::acos(z) / M_PI * kThetaBins), 0, kThetaBins - 1);
}

int phiBin(const Eigen::Vector3d& d) {
  if (d.x() == 0 && d.y() == 0) return 0;
  return int(std::floor(std::atan2(d.y(), d.x()) / (2 * M_PI) * kPhiBins + 0.5)) & (kPhiBins - 1);
}

Eigen::Vector3d binDirection(int i, int j) {
  const double th = (i + 0.5) * M_PI / kThetaBins, ph = 2 * M_PI * j / kPhiBins;
  return {std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th)};
}

// From voxel centre (x, y, z) along unit direction e: distance to the first known voxel's entry
// (0: this one), or to the grid's end where none is met, in frame units. (Known, not only
// occupied: a ray that passes a known voxel takes no height field, so a jump must not skip one.)
double firstKnown(const CellGrid& g, int x, int y, int z, const Eigen::Vector3d& e) {
  const double vs[3] = {g.vx, g.vy, g.vz};
  const int N[3] = {g.nx, g.ny, g.nz};
  int idx[3] = {x, y, z}, step[3];
  double tMax[3], tDelta[3];
  for (int k = 0; k < 3; ++k) {
    step[k] = e[k] > 0 ? 1 : (e[k] < 0 ? -1 : 0);
    tDelta[k] = e[k] != 0 ? vs[k] / std::abs(e[k]) : INFINITY;
    tMax[k] = e[k] != 0 ? 0.5 * tDelta[k] : INFINITY;
  }
  double t = 0;
  for (;;) {
    if (g.at(idx[0], idx[1], idx[2]) != kVoxelUnknown) return t;
    const int a = tMax[0] <= tMax[1] ? (tMax[0] <= tMax[2] ? 0 : 2) : (tMax[1] <= tMax[2] ? 1 : 2);
    t = tMax[a];
    idx[a] += step[a];
    if (idx[a] < 0 || idx[a] >= N[a]) return t;
    tMax[a] += tDelta[a];
  }
}

float toHalf(float f) { return float(Eigen::half(f)); }

}  // namespace

bool trace(const CellRecord& c, const CellGrid& g, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t0, double t1,
           double& tHit, Eigen::Vector3d* normal, uint32_t* steps, bool* touched) {
  if (touched) *touched = false;
  if (g.nx == 0 || !(t0 <= t1)) return false;
  uint32_t n = 0;
  bool tch = false;
  const bool hit = walk(c, g, o, d, t0, t1, t0, tHit, normal, n, tch);
  if (steps) *steps = n;
  if (touched) *touched = tch;
  return hit;
}

std::vector<float> sampleFunction(const CellGrid& g) {
  const size_t rows = size_t(g.nx) * g.ny * kPhiBins, cols = size_t(g.nz) * kThetaBins;
  std::vector<float> m(rows * cols);
  const double unit = std::min({g.vx, g.vy, g.vz});
  Eigen::Vector3d dirs[kThetaBins][kPhiBins];
  for (int i = 0; i < kThetaBins; ++i)
    for (int j = 0; j < kPhiBins; ++j) dirs[i][j] = binDirection(i, j);
  for (int y = 0; y < g.ny; ++y)
    for (int x = 0; x < g.nx; ++x)
      for (int j = 0; j < kPhiBins; ++j) {
        float* row = m.data() + ((size_t(y) * g.nx + x) * kPhiBins + j) * cols;
        for (int z = 0; z < g.nz; ++z)
          for (int i = 0; i < kThetaBins; ++i) row[z * kThetaBins + i] = float(firstKnown(g, x, y, z, dirs[i][j]) / unit);
      }
  return m;
}

namespace {

// Makes the sampled function a safer bound for the rays the shader asks about, which start
// anywhere in the entry voxel and point anywhere in the nearest bin: per voxel and bin, the
// smallest value over the neighbouring bins (theta +-1, phi +-1), then over the rays of the six
// face neighbours, each moved onto this voxel's ray (plus the offset between the centres along
// the bin's direction). Measured on a 40x40x20 cell: without the neighbours' rays 0.7 % of guided
// rays answered differently from the whole walk, with the six 0.03 % (the 26: 0.005 %, but
// walking 12 % more).
void lowerBound(const CellGrid& g, std::vector<float>& m) {
  const size_t cols = size_t(g.nz) * kThetaBins;
  const size_t rowsPerVoxel = kPhiBins;
  std::vector<float> a(m.size());
  // Directions: rows hold phi (within a voxel's 32 rows), columns theta.
  for (size_t vox = 0; vox < size_t(g.nx) * g.ny; ++vox)
    for (int j = 0; j < kPhiBins; ++j)
      for (int z = 0; z < g.nz; ++z)
        for (int i = 0; i < kThetaBins; ++i) {
          float v = INFINITY;
          for (int dj = -1; dj <= 1; ++dj) {
            const float* row = m.data() + (vox * rowsPerVoxel + ((j + dj) & (kPhiBins - 1))) * cols + size_t(z) * kThetaBins;
            for (int di = std::max(i - 1, 0); di <= std::min(i + 1, kThetaBins - 1); ++di) v = std::min(v, row[di]);
          }
          a[(vox * rowsPerVoxel + j) * cols + size_t(z) * kThetaBins + i] = v;
        }
  // Space: the six face neighbours.
  const double unit = std::min({g.vx, g.vy, g.vz});
  const int off[6][3] = {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};
  float along[6][kThetaBins][kPhiBins];
  for (int n = 0; n < 6; ++n) {
    const Eigen::Vector3d delta(off[n][0] * g.vx, off[n][1] * g.vy, off[n][2] * g.vz);
    for (int i = 0; i < kThetaBins; ++i)
      for (int j = 0; j < kPhiBins; ++j) along[n][i][j] = float(delta.dot(binDirection(i, j)) / unit);
  }
  for (int y = 0; y < g.ny; ++y)
    for (int x = 0; x < g.nx; ++x)
      for (int j = 0; j < kPhiBins; ++j)
        for (int z = 0; z < g.nz; ++z)
          for (int i = 0; i < kThetaBins; ++i) {
            float v = a[((size_t(y) * g.nx + x) * kPhiBins + j) * cols + size_t(z) * kThetaBins + i];
            for (int n = 0; n < 6; ++n) {
              const int xx = x + off[n][0], yy = y + off[n][1], zz = z + off[n][2];
              if (xx < 0 || yy < 0 || zz < 0 || xx >= g.nx || yy >= g.ny || zz >= g.nz) continue;
              v = std::min(v, std::max(0.0f, a[((size_t(yy) * g.nx + xx) * kPhiBins + j) * cols + size_t(zz) * kThetaBins + i] +
                                                 along[n][i][j]));
            }
            m[((size_t(y) * g.nx + x) * kPhiBins + j) * cols + size_t(z) * kThetaBins + i] = v;
          }
}

}  // namespace

double skippableVoxels(const CellRecord& c, const CellGrid& g, int rays) {
  if (g.nx == 0 || rays <= 0) return 0;
  std::mt19937 rng(g.cell);
  std::uniform_real_distribution<double> unit(0, 1);
  std::normal_distribution<double> gauss;
  const Eigen::Vector3d lo(c.box[0], c.box[2], c.box[4]), hi(c.box[1], c.box[3], c.box[5]), size = hi - lo;
  const Eigen::Vector3d vs(g.vx, g.vy, g.vz);
  double sum = 0;
  for (int k = 0; k < rays; ++k) {
    Eigen::Vector3d d(gauss(rng), gauss(rng), gauss(rng));
    d.normalize();
    const Eigen::Vector3d inBox = lo + Eigen::Vector3d(unit(rng), unit(rng), unit(rng)).cwiseProduct(size);
    const Eigen::Vector3d o = inBox - d * (2 * size.norm());
    double t0 = 0, t1 = 1e300;
    if (!clipRayToBox(lo, hi, o, d, t0, t1)) continue;
    // The voxels before the first known one, as many as the DDA would step through.
    const int steps = 4 * (g.nx + g.ny + g.nz);
    double skipped = 0;
    for (int i = 0; i < steps; ++i) {
      const double t = t0 + (t1 - t0) * (i + 0.5) / steps;
      const Eigen::Vector3d q = (o + d * t - lo).cwiseQuotient(vs);
      const int x = std::clamp(int(q.x()), 0, g.nx - 1), y = std::clamp(int(q.y()), 0, g.ny - 1), z = std::clamp(int(q.z()), 0, g.nz - 1);
      if (g.at(x, y, z) != kVoxelUnknown) break;
      skipped = (t - t0) * (std::abs(d.x()) / g.vx + std::abs(d.y()) / g.vy + std::abs(d.z()) / g.vz);
    }
    sum += skipped;
  }
  return sum / rays;
}

void bakeFunction(CellGrid& g, double maxError, uint64_t maxEntries) {
  g.fn = Function{};
  const uint64_t rows = uint64_t(g.nx) * g.ny * kPhiBins, cols = uint64_t(g.nz) * kThetaBins;
  if (g.nx == 0 || rows * cols > maxEntries || cols > 2048) return;
  // No ray through a grid of fewer than kDirectVoxels voxels along its three sides together
  // crosses that many: the traces never look the function up there (lone-star's 8290 forced
  // cells: most of them, and of a 303 MiB section).
  if (g.nx + g.ny + g.nz < kDirectVoxels) return;
  std::vector<float> raw = sampleFunction(g);
  lowerBound(g, raw);
  using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const Eigen::Map<const RowMajor> M(raw.data(), Eigen::Index(rows), Eigen::Index(cols));
  // The right singular vectors: eigenvectors of M^T M (cols x cols), largest first; the left
  // factor of rank k is then the first k columns of M V.
  const Eigen::MatrixXf G = M.transpose() * M;  // float products (the largest: 2^25 values, 2048 columns)
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(G.cast<double>());
  const int maxRank = int(std::min<uint64_t>({uint64_t(kMaxRank), rows, cols}));
  const Eigen::MatrixXf V = eig.eigenvectors().rightCols(maxRank).rowwise().reverse().cast<float>().unaryExpr(&toHalf);
  const Eigen::MatrixXf U = (M * V).unaryExpr(&toHalf);
  // The rank: the smallest whose error (as stored, in halves) is within maxError at the 95th
  // percentile, measured on up to 2^16 entries spread evenly over the matrix.
  const uint64_t n = rows * cols, stride = std::max<uint64_t>(1, n >> 16);
  std::vector<float> err;
  for (int k = 1; k <= maxRank; ++k) {
    err.clear();
    for (uint64_t e = 0; e < n; e += stride) {
      const Eigen::Index r = Eigen::Index(e / cols), q = Eigen::Index(e % cols);
      err.push_back(std::abs(U.row(r).head(k).dot(V.row(q).head(k)) - M(r, q)));
    }
    const size_t i95 = size_t(0.95 * double(err.size() - 1)), i99 = size_t(0.99 * double(err.size() - 1));
    std::nth_element(err.begin(), err.begin() + i99, err.end());
    const double p99 = err[i99];
    std::nth_element(err.begin(), err.begin() + i95, err.begin() + i99);
    const double p95 = err[i95];
    if (p95 <= maxError || k == maxRank) {
      g.fn.rank = k;
      g.fn.p95 = p95;
      g.fn.p99 = p99;
      g.fn.u.resize(size_t(rows) * k);
      g.fn.v.resize(size_t(cols) * k);
      for (uint64_t r = 0; r < rows; ++r)
        for (int q = 0; q < k; ++q) g.fn.u[r * k + q] = U(Eigen::Index(r), q);
      for (uint64_t r = 0; r < cols; ++r)
        for (int q = 0; q < k; ++q) g.fn.v[r * k + q] = V(Eigen::Index(r), q);
      return;
    }
  }
}

double lookup(const CellGrid& g, int x, int y, int z, const Eigen::Vector3d& d) {
  const int k = g.fn.rank;
  const size_t row = (size_t(y) * g.nx + x) * kPhiBins + phiBin(d), col = size_t(z) * kThetaBins + thetaBin(d);
  float s = 0;
  for (int q = 0; q < k; ++q) s += g.fn.u[row * k + q] * g.fn.v[col * k + q];
  return s;
}

int voxelsCrossed(const CellGrid& g, const Eigen::Vector3d& d, double t0, double t1) {
  const double n = (t1 - t0) * (std::abs(d.x()) / g.vx + std::abs(d.y()) / g.vy + std::abs(d.z()) / g.vz);
  return n < 1e9 ? int(n) + 1 : 1000000000;
}

bool traceGuided(const CellRecord& c, const CellGrid& g, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t0,
                 double t1, double& tHit, Eigen::Vector3d* normal, uint32_t* steps, bool* touched, Guided* how) {
  if (how) *how = Guided::kNone;
  if (g.fn.rank == 0 || g.nx == 0 || !(t0 <= t1) || voxelsCrossed(g, d, t0, t1) <= kDirectVoxels)
    return trace(c, g, o, d, t0, t1, tHit, normal, steps, touched);
  const Eigen::Vector3d vs(g.vx, g.vy, g.vz), lo = gridMin(c);
  const double unit = vs.minCoeff(), len = d.norm();
  auto voxelAt = [&](double t, int b[3]) {
    const Eigen::Vector3d q = o + d * t - lo;
    for (int k = 0; k < 3; ++k) b[k] = std::clamp(int(std::floor(q[k] / vs[k])), 0, (k == 0 ? g.nx : k == 1 ? g.ny : g.nz) - 1);
  };
  // Jumps: at most kMaxJumps lookups, each from the voxel the ray has reached, less a margin for
  // the compression error; a jump is taken only when the voxel half a voxel before where it lands
  // is empty (else the function overestimated there: walk from where the ray was).
  double t = t0;
  int jumps = 0;
  bool failed = false;
  while (jumps < kMaxJumps && t < t1) {
    int idx[3];
    voxelAt(t, idx);
    ++jumps;
    const double skip = (lookup(g, idx[0], idx[1], idx[2], d) - 0.5) * unit / len;
    if (skip < unit / len) break;  // less than a voxel: walk
    const double tn = std::min(t + skip, t1);
    int b[3];
    voxelAt(tn - 0.5 * unit / len, b);
    if (g.at(b[0], b[1], b[2]) != kVoxelUnknown) {
      failed = true;
      break;
    }
    t = tn;
  }
  uint32_t n = 0;
  bool tch = false;
  const bool hit = t < t1 && walk(c, g, o, d, t, t1, t0, tHit, normal, n, tch);
  if (how) *how = failed ? Guided::kFallback : hit ? Guided::kHit : Guided::kMiss;
  if (steps) *steps = n + uint32_t(jumps);  // a lookup counts as one
  if (touched) *touched = tch;
  return hit;
}

namespace {

// The pack's sources, relative to its origin: points (with normals where the files have them)
// and, for a single mesh file, its triangles.
class Collect : public BatchSink {
 public:
  explicit Collect(const double origin[3]) { std::copy(origin, origin + 3, o_); }
  Status onPoints(const PointBatch& b) override {
    for (size_t i = 0; i < b.size(); ++i) {
      p.emplace_back(b.x[i] - o_[0], b.y[i] - o_[1], b.z[i] - o_[2]);
      n.push_back(b.hasNormals() ? Eigen::Vector3d(b.nx[i], b.ny[i], b.nz[i]) : Eigen::Vector3d::Zero());
      scan.push_back(b.scan.empty() ? uint16_t(0) : b.scan[i]);
      normals = normals || b.hasNormals();
    }
    return Status::ok();
  }
  Status onTriangles(const uint32_t* idx, size_t count) override {
    tris.insert(tris.end(), idx, idx + 3 * count);
    return Status::ok();
  }
  std::vector<Eigen::Vector3d> p, n;
  std::vector<uint16_t> scan;
  std::vector<uint32_t> tris;
  bool normals = false;  // some file gave normals

 private:
  double o_[3];
};

// Points that came without normals: the pack's own estimate (fitSurface as the pack calls it,
// without smoothing: the field averages the noise itself), outliers' normals zeroed so the grid
// leaves them out. pos/n/scan: the cell's samples, in its frame.
void estimateSampleNormals(const PackReader& pack, const InputSet& input, const CellRecord& c, Samples& s,
                           const std::vector<uint16_t>& scan) {
  const size_t m = s.p.size();
  if (m == 0) return;
  std::vector<double> pos(3 * m);
  for (size_t i = 0; i < m; ++i) std::copy(s.p[i].data(), s.p[i].data() + 3, &pos[3 * i]);
  const Eigen::Vector3d O(c.origin), U(c.u), V(c.v), W(c.w);
  auto toFrame = [&](const Eigen::Vector3d& x) { return Eigen::Vector3d(x.dot(U), x.dot(V), x.dot(W)); };
  NormalOrientation orient;
  for (const Eigen::Vector3d& t : input.towardScanner()) orient.towardScanner.push_back(toFrame(t));
  orient.scan = scan.empty() ? nullptr : scan.data();
  orient.scanStride = sizeof(uint16_t);
  const Eigen::Vector3d centre = 0.5 * (Eigen::Vector3d(pack.meta().boundsMin) + Eigen::Vector3d(pack.meta().boundsMax));
  orient.center = toFrame(centre - O);
  SurfaceOptions so;
  so.smooth = false;
  std::vector<float> nrm(3 * m, 0.f);
  std::vector<uint8_t> keep;
  fitSurface(pos.data(), m, orient, so, nrm.data(), keep);
  for (size_t i = 0; i < m; ++i) s.n[i] = keep[i] ? Eigen::Vector3d(nrm[3 * i], nrm[3 * i + 1], nrm[3 * i + 2]) : Eigen::Vector3d::Zero();
}

// The sources' points, or triangles, in a uniform grid of buckets (relative to the pack origin),
// so that a cell visits only those near its box instead of all of them (lone-star: 518862 points
// tested against each of 8290 forced cells). A triangle goes into every bucket its bounds meet.
class Buckets {
 public:
  Buckets(const Collect& all, bool triangles, double size) : size_(std::max(size, 1e-300)) {
    auto key = [&](const Eigen::Vector3d& p, int k) { return int64_t(std::floor(p[k] / size_)); };
    if (!triangles) {
      for (size_t i = 0; i < all.p.size(); ++i) map_[pack(key(all.p[i], 0), key(all.p[i], 1), key(all.p[i], 2))].push_back(uint32_t(i));
      return;
    }
    for (size_t t = 0; t + 2 < all.tris.size(); t += 3) {
      const Eigen::Vector3d& a = all.p[all.tris[t]], &b = all.p[all.tris[t + 1]], &c = all.p[all.tris[t + 2]];
      const Eigen::Vector3d lo = a.cwiseMin(b).cwiseMin(c), hi = a.cwiseMax(b).cwiseMax(c);
      forRange(lo, hi, [&](uint64_t k) { map_[k].push_back(uint32_t(t / 3)); });
    }
  }
  // The items of the buckets [lo, hi] meets, each once, in increasing order.
  std::vector<uint32_t> near(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const {
    std::vector<uint32_t> out;
    forRange(lo, hi, [&](uint64_t k) {
      auto it = map_.find(k);
      if (it != map_.end()) out.insert(out.end(), it->second.begin(), it->second.end());
    });
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
  }

 private:
  static uint64_t pack(int64_t x, int64_t y, int64_t z) {
    auto u = [](int64_t v) { return uint64_t(v + (int64_t(1) << 20)) & ((uint64_t(1) << 21) - 1); };
    return u(x) << 42 | u(y) << 21 | u(z);
  }
  template <class F>
  void forRange(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, F f) const {
    int64_t a[3], b[3];
    for (int k = 0; k < 3; ++k) {
      a[k] = int64_t(std::floor(lo[k] / size_));
      b[k] = std::max(a[k], int64_t(std::floor(hi[k] / size_)));
    }
    for (int64_t z = a[2]; z <= b[2]; ++z)
      for (int64_t y = a[1]; y <= b[1]; ++y)
        for (int64_t x = a[0]; x <= b[0]; ++x) f(pack(x, y, z));
  }
  double size_;
  std::unordered_map<uint64_t, std::vector<uint32_t>> map_;
};

// A forced cell's source samples in its frame, within pad of its box: a single mesh's triangles
// sampled half a voxel apart with their face normals, else the points.
Samples cellSamples(const Collect& all, const Buckets& buckets, bool meshes, const CellRecord& c, double pad,
                    std::vector<uint16_t>& scan) {
  const Eigen::Vector3d O(c.origin), U(c.u), V(c.v), W(c.w);
  const double vx = (c.box[1] - c.box[0]) / c.tileW, vy = (c.box[3] - c.box[2]) / c.tileH;
  auto frame = [&](const Eigen::Vector3d& p) { const Eigen::Vector3d r = p - O; return Eigen::Vector3d(r.dot(U), r.dot(V), r.dot(W)); };
  auto inside = [&](const Eigen::Vector3d& f) {
    return f.x() >= c.box[0] - pad && f.x() <= c.box[1] + pad && f.y() >= c.box[2] - pad && f.y() <= c.box[3] + pad &&
           f.z() >= c.box[4] - pad && f.z() <= c.box[5] + pad;
  };
  Eigen::Vector3d blo, bhi;
  cellBounds(c, pad, blo, bhi);
  const std::vector<uint32_t> near = buckets.near(blo, bhi);
  Samples s;
  if (meshes) {
    const double step = 0.5 * std::min(vx, vy);
    for (uint32_t tri : near) {
      const size_t t = 3 * size_t(tri);
      const Eigen::Vector3d a = frame(all.p[all.tris[t]]), b = frame(all.p[all.tris[t + 1]]), cc = frame(all.p[all.tris[t + 2]]);
      const Eigen::Vector3d lo = a.cwiseMin(b).cwiseMin(cc), hi = a.cwiseMax(b).cwiseMax(cc);
      if (hi.x() < c.box[0] - pad || lo.x() > c.box[1] + pad || hi.y() < c.box[2] - pad || lo.y() > c.box[3] + pad ||
          hi.z() < c.box[4] - pad || lo.z() > c.box[5] + pad)
        continue;
      const Eigen::Vector3d fn = (b - a).cross(cc - a);
      if (fn.squaredNorm() == 0) continue;
      const int m = std::clamp(int(std::ceil(std::max({(b - a).norm(), (cc - a).norm(), (cc - b).norm()}) / step)), 1, 512);
      for (int i = 0; i <= m; ++i)
        for (int j = 0; i + j <= m; ++j) {
          const Eigen::Vector3d q = a + (b - a) * (double(i) / m) + (cc - a) * (double(j) / m);
          if (!inside(q)) continue;
          s.p.push_back(q);
          s.n.push_back(fn.normalized());
        }
    }
    return s;
  }
  for (uint32_t i : near) {
    const Eigen::Vector3d f = frame(all.p[i]);
    if (!inside(f)) continue;
    s.p.push_back(f);
    const Eigen::Vector3d& nw = all.n[i];
    s.n.push_back(nw.squaredNorm() > 0 ? Eigen::Vector3d(nw.dot(U), nw.dot(V), nw.dot(W)) : Eigen::Vector3d::Zero());
    scan.push_back(all.scan[i]);
  }
  return s;
}

// The pad a cell gathers samples within: as far from the box as the kernel reaches (buildGrid),
// for points also their neighbours' reach for the normals.
double samplePad(const CellRecord& c, bool triangles, double spacing) {
  const double vx = (c.box[1] - c.box[0]) / c.tileW, vy = (c.box[3] - c.box[2]) / c.tileH;
  return triangles ? 2 * std::max(vx, vy) : 3.5 * spacing + std::max(vx, vy);
}

}  // namespace

// A function of the given rank's bytes in the section.
namespace {
uint64_t functionBytes(const CellGrid& g, uint64_t rank) {
  return 4 * (((uint64_t(g.nx) * g.ny * kPhiBins * rank) + 1) / 2 + ((uint64_t(g.nz) * kThetaBins * rank) + 1) / 2);
}
}  // namespace

uint64_t functionBytes(const CellGrid& g) { return functionBytes(g, uint64_t(g.fn.rank)); }

// The direction functions where they pay, under a byte budget: the cells whose random rays would
// skip kWorthAFunction voxels or more (the real scans' forced cells skip 1.3-1.7 at the median,
// about what a lookup costs; lone-star's 8290 cells had 303 MiB of functions, most of a 4-minute
// bake), most skipped first, baked 16 at a time; a function is kept while its bytes still fit, and
// after a batch that kept none the rest are left out. The batches do not depend on the machine,
// so neither do the bytes. tick: once per cell looked at.
void bakeFunctions(std::vector<CellGrid>& grids, const std::vector<double>& skip, uint64_t budget, FunctionReport* report,
                   const std::function<void()>& tick0) {
  auto tick = [&] {
    if (tick0) tick0();
  };
  std::vector<size_t> order;
  for (size_t k = 0; k < grids.size(); ++k) {
    if (grids[k].nx > 0 && skip[k] >= kWorthAFunction) order.push_back(k);
    else tick();
  }
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return skip[a] > skip[b]; });
  FunctionReport rep;
  rep.candidates = uint32_t(order.size());
  constexpr size_t kBatch = 16;
  for (size_t at = 0; at < order.size(); at += kBatch) {
    const size_t end = std::min(order.size(), at + kBatch);
    tbb::parallel_for(at, end, [&](size_t i) {
      CellGrid& g = grids[order[i]];
      // A rank-1 function is the least it can take: not even that fits, nothing to bake.
      if (rep.bytes + functionBytes(g, 1) <= budget) bakeFunction(g);
      tick();
    });
    bool kept = false;
    for (size_t i = at; i < end; ++i) {
      CellGrid& g = grids[order[i]];
      const uint64_t b = functionBytes(g);
      if (g.fn.rank > 0 && rep.bytes + b <= budget) {
        rep.bytes += b;
        ++rep.baked;
        kept = true;
      } else {
        ++rep.overBudget;
        g.fn = Function{};
      }
    }
    if (!kept) {  // the budget is full for cells like these: the rest are left out unbaked
      rep.overBudget += uint32_t(order.size() - end);
      for (size_t i = end; i < order.size(); ++i) tick();
      break;
    }
  }
  if (report) *report = rep;
}

Result<std::vector<CellGrid>> buildForcedGrids(const PackReader& pack, uint64_t functionBudget, FunctionReport* report,
                                               const std::function<void(uint64_t, uint64_t)>& progress) {
  std::vector<uint32_t> forced;
  auto cells = pack.cells();
  for (uint32_t i = 0; i < cells.size(); ++i)
    if (cells[i].flags & kCellForced) forced.push_back(i);
  std::vector<CellGrid> grids(forced.size());
  if (forced.empty()) return grids;
  auto input = openPackSources(pack, "gdm builds its voxels from the sources");
  if (!input) return input.status();
  Collect all(pack.meta().origin);
  const bool meshes = input->hasTriangles();
  SA_RETURN_IF_ERROR(input->stream(all, meshes));
  const bool triangles = meshes && !all.tris.empty();
  const double spacing = pack.meta().sampleSpacing;
  // Buckets the size of the median forced cell's bounds.
  std::vector<double> extent;
  for (uint32_t i : forced) {
    Eigen::Vector3d lo, hi;
    cellBounds(cells[i], samplePad(cells[i], triangles, spacing), lo, hi);
    extent.push_back((hi - lo).maxCoeff());
  }
  std::nth_element(extent.begin(), extent.begin() + extent.size() / 2, extent.end());
  const Buckets buckets(all, triangles, extent[extent.size() / 2]);
  std::atomic<uint64_t> done{0};
  std::mutex m;
  auto tick = [&](uint64_t total) {
    const uint64_t d = ++done;
    if (progress) {
      std::lock_guard<std::mutex> lock(m);
      progress(d, total);
    }
  };
  const uint64_t total = 2 * forced.size();
  std::vector<double> skip(forced.size(), 0);
  tbb::parallel_for(size_t(0), forced.size(), [&](size_t k) {
    const CellRecord& c = cells[forced[k]];
    std::vector<uint16_t> scan;
    Samples s = cellSamples(all, buckets, triangles, c, samplePad(c, triangles, spacing), scan);
    if (!triangles && !all.normals) estimateSampleNormals(pack, *input, c, s, scan);
    grids[k] = buildGrid(c, forced[k], s, triangles ? 0 : spacing);
    skip[k] = skippableVoxels(c, grids[k]);
    tick(total);
  });
  bakeFunctions(grids, skip, functionBudget, report, [&] { tick(total); });
  return grids;
}

namespace {

// Halves two to a word, low half first; an odd count leaves the last high half zero.
void appendHalves(std::vector<uint32_t>& words, const std::vector<float>& values) {
  for (size_t i = 0; i < values.size(); i += 2) {
    const uint16_t lo = Eigen::half(values[i]).x, hi = i + 1 < values.size() ? Eigen::half(values[i + 1]).x : 0;
    words.push_back(uint32_t(lo) | uint32_t(hi) << 16);
  }
}

std::vector<float> readHalves(const uint32_t* words, size_t count) {
  std::vector<float> out(count);
  for (size_t i = 0; i < count; ++i) {
    Eigen::half h;
    h.x = uint16_t(words[i / 2] >> (16 * (i % 2)));
    out[i] = float(h);
  }
  return out;
}

uint64_t halfWords(uint64_t halves) { return (halves + 1) / 2; }

}  // namespace

ExtraSection makeSection(const PackReader& pack, const std::vector<CellGrid>& grids, double bakeSeconds) {
  std::vector<uint32_t> entries(pack.cells().size(), kNoEntry), words;
  uint32_t count = 0;
  for (const CellGrid& g : grids) {
    if (g.nx == 0) continue;
    entries[g.cell] = uint32_t(words.size());
    const float v[3] = {float(g.vx), float(g.vy), float(g.vz)};
    uint32_t vb[3];
    std::memcpy(vb, v, 12);
    const uint64_t sw = stateWords(g.state.size()), cw = cornerWords(g.corners.size());
    const uint32_t fnStart = uint32_t(kBlockHeaderWords + sw + cw);
    const uint32_t head[kBlockHeaderWords] = {uint32_t(g.nx), uint32_t(g.ny), uint32_t(g.nz), vb[0], vb[1], vb[2],
                                              uint32_t(g.fn.rank), g.fn.rank ? fnStart : 0u};
    words.insert(words.end(), head, head + kBlockHeaderWords);
    const size_t states = words.size();
    words.resize(states + sw + cw, 0u);
    for (size_t i = 0; i < g.state.size(); ++i) words[states + i / 16] |= uint32_t(g.state[i] & 3u) << (2 * (i % 16));
    for (size_t i = 0; i < g.corners.size(); ++i)
      words[states + sw + i / 2] |= uint32_t(uint16_t(g.corners[i])) << (16 * (i % 2));
    if (g.fn.rank) {
      appendHalves(words, g.fn.u);
      appendHalves(words, g.fn.v);
    }
    ++count;
  }
  SectionHeader h{};
  h.version = kSectionVersion;
  h.cellCount = uint32_t(pack.cells().size());
  h.gridCells = count;
  h.bakeSeconds = bakeSeconds;
  h.wordCount = words.size();
  ExtraSection s;
  std::memcpy(s.id, kSectionId, 4);
  s.bytes.resize(sizeof(h) + 4 * (entries.size() + words.size()));
  std::memcpy(s.bytes.data(), &h, sizeof(h));
  std::memcpy(s.bytes.data() + sizeof(h), entries.data(), 4 * entries.size());
  if (!words.empty()) std::memcpy(s.bytes.data() + sizeof(h) + 4 * entries.size(), words.data(), 4 * words.size());
  return s;
}

Result<SectionView> readSection(const PackReader& pack) {
  const std::span<const uint8_t> b = pack.section(kSectionId);
  SectionView v;
  if (b.empty()) return v;
  const std::string where = pack.path() + ": section GDMV (the gdm mode's voxel grids): ";
  if (b.size() < sizeof(SectionHeader)) return Status::badInput(where + "too short");
  std::memcpy(&v.header, b.data(), sizeof(SectionHeader));
  const SectionHeader& h = v.header;
  if (h.version != kSectionVersion)
    return Status::badInput(where + "version " + std::to_string(h.version) + ", this program reads version " +
                            std::to_string(kSectionVersion) + "; bake it again: scanatlas bake PACK --mode gdm");
  if (h.cellCount != pack.cells().size()) return Status::badInput(where + "made for another cell table (bake it again)");
  if (h.wordCount > b.size() / 4 || sizeof(SectionHeader) + 4 * (uint64_t(h.cellCount) + h.wordCount) != b.size())
    return Status::badInput(where + "its size does not match its header");
  v.entries = reinterpret_cast<const uint32_t*>(b.data() + sizeof(SectionHeader));
  v.words = v.entries + h.cellCount;
  for (uint32_t i = 0; i < h.cellCount; ++i) {
    const uint32_t e = v.entries[i];
    if (e == kNoEntry) continue;
    if (uint64_t(e) + kBlockHeaderWords > h.wordCount) return Status::badInput(where + "cell " + std::to_string(i) + " lies outside");
    const uint32_t* blk = v.words + e;
    const CellRecord& c = pack.cells()[i];
    const uint64_t voxels = uint64_t(blk[0]) * blk[1] * blk[2], rank = blk[6];
    const uint64_t gridWords = blk[2] > 1024 ? 0 : stateWords(voxels) + cornerWords(uint64_t(blk[0] + 1) * (blk[1] + 1) * (blk[2] + 1));
    float vsz[3];
    std::memcpy(vsz, blk + 3, 12);
    bool bad = blk[0] != c.tileW || blk[1] != c.tileH || blk[2] == 0 || blk[2] > 1024 ||
               !(vsz[0] > 0 && vsz[1] > 0 && vsz[2] > 0 && std::isfinite(vsz[0] * vsz[1] * vsz[2])) ||
               uint64_t(e) + kBlockHeaderWords + gridWords > h.wordCount || rank > uint64_t(kMaxRank);
    if (!bad && rank) {
      const uint64_t fnWords = halfWords(voxels / blk[2] * kPhiBins * rank) + halfWords(uint64_t(blk[2]) * kThetaBins * rank);
      bad = blk[7] != kBlockHeaderWords + gridWords || uint64_t(e) + blk[7] + fnWords > h.wordCount;
    }
    if (bad) return Status::badInput(where + "cell " + std::to_string(i) + "'s block is inconsistent (bake it again)");
  }
  v.present = true;
  v.bytes = b.size();
  return v;
}

CellGrid gridFromSection(const PackReader& pack, const SectionView& v, uint32_t cell) {
  (void)pack;
  CellGrid g;
  g.cell = cell;
  const uint32_t* blk = v.words + v.entries[cell];
  g.nx = int(blk[0]);
  g.ny = int(blk[1]);
  g.nz = int(blk[2]);
  float f[3];
  std::memcpy(f, blk + 3, 12);
  g.vx = f[0];
  g.vy = f[1];
  g.vz = f[2];
  const size_t voxels = g.voxelCount(), corners = size_t(g.nx + 1) * (g.ny + 1) * (g.nz + 1);
  const uint32_t* st = blk + kBlockHeaderWords;
  const uint32_t* cw = st + stateWords(voxels);
  g.state.resize(voxels);
  for (size_t i = 0; i < voxels; ++i) g.state[i] = uint8_t((st[i / 16] >> (2 * (i % 16))) & 3u);
  g.corners.resize(corners);
  for (size_t i = 0; i < corners; ++i) g.corners[i] = int16_t(uint16_t(cw[i / 2] >> (16 * (i % 2))));
  g.fn.rank = int(blk[6]);
  if (g.fn.rank) {
    const uint64_t uHalves = uint64_t(g.nx) * g.ny * kPhiBins * g.fn.rank;
    g.fn.u = readHalves(blk + blk[7], uHalves);
    g.fn.v = readHalves(blk + blk[7] + halfWords(uHalves), uint64_t(g.nz) * kThetaBins * g.fn.rank);
  }
  return g;
}

}  // namespace sa::gdm
