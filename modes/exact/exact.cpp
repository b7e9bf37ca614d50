#include "modes/exact/exact.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <cmath>
#include <limits>

namespace sa::exact {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// One bilinear piece of a patch: its four corner heights (00, 10, 01, 11) and whether it is covered.
struct Piece {
  bool covered = false;
  double h[4] = {0, 0, 0, 0};
};

// Patch (px, py) lies between texels (px - 1, py - 1) and (px, py). Unmixed: piece[0] is the whole
// patch. Mixed (a corner uncovered): piece[q] is the quadrant nearest corner q (q = qx + 2 qy).
struct Patch {
  bool mixed = false;
  Piece piece[4];
};

class Surface {
 public:
  Surface(const PackReader& pack, const CellRecord& c) : pack_(pack), c_(c) {
    tu_ = (c.box[1] - c.box[0]) / c.tileW;
    tv_ = (c.box[3] - c.box[2]) / c.tileH;
  }

  Patch patch(int px, int py) const {
    const int i0 = px - 1, j0 = py - 1;
    double h[4];
    bool cov[4], all = true;
    for (int k = 0; k < 4; ++k) {
      const int i = std::clamp(i0 + (k & 1), -1, int(c_.tileW)), j = std::clamp(j0 + (k >> 1), -1, int(c_.tileH));
      const uint16_t code = pack_.texel(c_, i, j);
      cov[k] = code != 0;
      h[k] = cov[k] ? decodeHeight(code, c_.box[4], c_.box[5]) : 0.0;
      all = all && cov[k];
    }
    Patch p;
    if (all) {
      p.piece[0].covered = true;
      std::copy(h, h + 4, p.piece[0].h);
      return p;
    }
    p.mixed = true;
    for (int q = 0; q < 4; ++q) {
      Piece& pc = p.piece[q];
      pc.covered = cov[q];
      if (!pc.covered) continue;
      const int ni = std::clamp(i0 + (q & 1), 0, int(c_.tileW) - 1), nj = std::clamp(j0 + (q >> 1), 0, int(c_.tileH) - 1);
      double gu = 0, gv = 0;  // the tangent plane's slope (stored normal), frame units per texel
      if (pack_.hasNormals()) {
        double w[3];
        decodeNormal(pack_.normalTexel(c_, ni, nj), w);
        const double n[3] = {w[0] * c_.u[0] + w[1] * c_.u[1] + w[2] * c_.u[2],
                             w[0] * c_.v[0] + w[1] * c_.v[1] + w[2] * c_.v[2],
                             w[0] * c_.w[0] + w[1] * c_.w[1] + w[2] * c_.w[2]};
        gu = -n[0] / std::max(n[2], 0.05) * tu_;
        gv = -n[1] / std::max(n[2], 0.05) * tv_;
      }
      for (int k = 0; k < 4; ++k)
        pc.h[k] = cov[k] ? h[k] : h[q] + gu * (i0 + (k & 1) - ni) + gv * (j0 + (k >> 1) - nj);
      if (!pack_.hasNormals())
        for (int k = 0; k < 4; ++k) pc.h[k] = h[q];  // no normals: the nearest texel's height (sampleHeight)
    }
    return p;
  }

 private:
  const PackReader& pack_;
  const CellRecord& c_;
  double tu_, tv_;
};

uint16_t encodeUp(double v, double wMin, double wMax) {
  if (!(wMax > wMin)) return kNodeUnbounded;
  const double r = std::ceil((v - wMin) / (wMax - wMin) * 65534.0);
  if (r >= 65532) return kNodeUnbounded;  // at or near the box top (with the margin below)
  // One code of margin over rounding up: float traversals compare in single precision.
  return uint16_t(std::clamp(r, 0.0, 65531.0) + 2);
}

// A lower bound's code: rounded down, one code of margin; 0 = unbounded below (never skipped by it).
uint16_t encodeDown(double v, double wMin, double wMax) {
  if (!(wMax > wMin)) return 0;
  const double r = std::floor((v - wMin) / (wMax - wMin) * 65534.0);
  if (r < 1) return 0;
  return uint16_t(std::min(r, 65534.0));  // decodes to r - 1 codes above wMin: one code below the floor
}

double decodeNode(uint16_t k, double wMin, double wMax) {
  if (k == kNodeUnbounded) return kInf;
  return decodeHeight(k, wMin, wMax);
}

double decodeNodeMin(uint16_t k, double wMin, double wMax) { return k == 0 ? -kInf : decodeHeight(k, wMin, wMax); }

// The ray along one piece: g(s) = A + B s + C s^2 = w(s) - h(s), s in [0, L] from the piece's start.
struct Quadratic {
  double A, B, C;
  double at(double s) const { return A + s * (B + s * C); }
};

Quadratic gapOf(const Piece& p, double ax0, double ay0, double kx, double ky, double z0, double kz) {
  const double* h = p.h;
  const double e = h[0] - h[1] - h[2] + h[3];
  const double hA = h[0] + (h[1] - h[0]) * ax0 + (h[2] - h[0]) * ay0 + e * ax0 * ay0;
  const double hB = (h[1] - h[0]) * kx + (h[2] - h[0]) * ky + e * (ax0 * ky + ay0 * kx);
  const double hC = e * kx * ky;
  return {z0 - hA, kz - hB, -hC};
}

// First s in (0, L] where g falls to zero from above (the descending root), or -1.
double descendingRoot(const Quadratic& g, double L) {
  double roots[2];
  int n = 0;
  if (g.C == 0) {
    if (g.B != 0) roots[n++] = -g.A / g.B;
  } else {
    const double disc = g.B * g.B - 4 * g.A * g.C;
    if (disc < 0) return -1;
    const double q = -0.5 * (g.B + std::copysign(std::sqrt(disc), g.B));
    if (q != 0) roots[n++] = g.A / q;
    roots[n++] = q / g.C;
  }
  double best = -1;
  for (int k = 0; k < n; ++k) {
    const double r = roots[k];
    if (!(r > 0 && r <= L * (1 + 1e-9))) continue;  // a crossing on the box's far face counts
    if (g.B + 2 * g.C * r > 0) continue;  // rising through zero: leaving the surface upward
    if (best < 0 || r < best) best = r;
  }
  return std::min(best, L);
}

// The ray in patch coordinates: S = texel coordinate + 1 (patch p spans [p, p + 1)).
struct Ray {
  double S0[2], dS[2], z0, dz;
  double S(int a, double t) const { return S0[a] + dS[a] * t; }
  double z(double t) const { return z0 + dz * t; }
};

// Solves patch (px, py) over [ta, tb]. prevAbove: the ray was just above a covered piece.
bool solvePatch(const Surface& surf, const Ray& r, int px, int py, double ta, double tb, bool& prevAbove, double& tHit,
                TraceStats* st) {
  const Patch p = surf.patch(px, py);
  // Split at the quadrant lines of a mixed patch.
  double cuts[4] = {ta, tb, tb, tb};
  int nc = 1;
  if (p.mixed) {
    for (int a = 0; a < 2; ++a) {
      if (r.dS[a] == 0) continue;
      const double tq = ((a == 0 ? px : py) + 0.5 - r.S0[a]) / r.dS[a];
      if (tq > ta && tq < tb) cuts[nc++] = tq;
    }
    if (nc == 3 && cuts[2] < cuts[1]) std::swap(cuts[1], cuts[2]);
  }
  cuts[nc] = tb;
  for (int k = 0; k < nc; ++k) {
    const double s0 = cuts[k], s1 = cuts[k + 1], tm = 0.5 * (s0 + s1);
    const double ax0 = r.S(0, s0) - px, ay0 = r.S(1, s0) - py;
    int q = 0;
    if (p.mixed) q = (r.S(0, tm) - px >= 0.5 ? 1 : 0) + (r.S(1, tm) - py >= 0.5 ? 2 : 0);
    const Piece& pc = p.piece[q];
    if (st) ++st->pieces;
    if (!pc.covered) {
      prevAbove = false;
      continue;
    }
    const Quadratic g = gapOf(pc, ax0, ay0, r.dS[0], r.dS[1], r.z(s0), r.dz);
    if (g.A <= 0 && prevAbove) {
      tHit = s0;
      return true;
    }
    const double L = s1 - s0, root = descendingRoot(g, L);
    if (root > 0) {
      tHit = s0 + root;
      return true;
    }
    prevAbove = g.at(L) > 0;
  }
  return false;
}

int nodeIndex(double S, double dS) { return dS >= 0 ? int(std::floor(S)) : int(std::ceil(S)) - 1; }

bool trace(const PackReader& pack, const CellRecord& c, const uint16_t* codes, const Eigen::Vector3d& o,
           const Eigen::Vector3d& d, double t0, double t1, double& tHit, TraceStats* st) {
  const Surface surf(pack, c);
  const int W = c.tileW, H = c.tileH;
  const Levels lv = levelsOf(W, H);
  const double du = c.box[1] - c.box[0], dv = c.box[3] - c.box[2];
  const double sx = du > 0 ? W / du : 0, sy = dv > 0 ? H / dv : 0;
  Ray r;
  r.S0[0] = (o.x() - c.box[0]) * sx + 0.5;
  r.S0[1] = (o.y() - c.box[2]) * sy + 0.5;
  r.dS[0] = d.x() * sx;
  r.dS[1] = d.y() * sy;
  r.z0 = o.z();
  r.dz = d.z();
  if (!(t0 < t1)) return false;
  const int N[2] = {W + 1, H + 1};
  int pos[2];
  for (int a = 0; a < 2; ++a) pos[a] = std::clamp(nodeIndex(r.S(a, t0), r.dS[a]), 0, N[a] - 1);
  const int top = lv.count - 1;
  // Start at the level whose nodes are about as long as the ray's run over the tile: a steep
  // ray crosses a few patches of a large tile, and descending from the top costs a visit a level.
  const double run = std::max(std::abs(r.dS[0]), std::abs(r.dS[1])) * (t1 - t0);
  int l = 0;
  while (codes && l < top && double(1 << l) < run) ++l;
  bool prevAbove = false;
  double t = t0;
  TraceStats local;
  TraceStats& s = st ? *st : local;
  const uint32_t cap = maxNodeVisits(W, H);
  for (;;) {
    if (++s.nodeVisits > cap) {
      s.capped = true;
      return false;
    }
    const int n[2] = {pos[0] >> l, pos[1] >> l};
    double tx[2];
    for (int a = 0; a < 2; ++a) {
      if (r.dS[a] > 0) tx[a] = (double((n[a] + 1) << l) - r.S0[a]) / r.dS[a];
      else if (r.dS[a] < 0) tx[a] = (double(n[a] << l) - r.S0[a]) / r.dS[a];
      else tx[a] = kInf;
    }
    const double tOut = std::max(t, std::min({tx[0], tx[1], t1}));
    bool skip = false;
    double nodeMax = kInf;
    if (codes) {
      const uint16_t* node = codes + 2 * (lv.offset[l] + uint64_t(n[1]) * lv.w[l] + n[0]);
      nodeMax = decodeNode(node[0], c.box[4], c.box[5]);
      // Above every covered piece (no crossing can start), or below all of them with nothing
      // above to fall from (no piece is crossed from above: the sheet's underside).
      skip = node[0] == kNodeEmpty || std::min(r.z(t), r.z(tOut)) > nodeMax ||
             (!prevAbove && std::max(r.z(t), r.z(tOut)) < decodeNodeMin(node[1], c.box[4], c.box[5]));
    }
    if (!skip && l > 0) {
      // A descending ray is above the node's maximum until it reaches that height: no hit
      // before, so it moves there first (the position is kept inside this node).
      if (r.dz < 0 && nodeMax < kInf) {
        const double tPlane = (nodeMax - r.z0) / r.dz;
        if (tPlane > t && tPlane < tOut) {
          t = tPlane;
          prevAbove = false;
          for (int a = 0; a < 2; ++a)
            pos[a] = std::clamp(nodeIndex(r.S(a, t), r.dS[a]), n[a] << l, std::min(((n[a] + 1) << l) - 1, N[a] - 1));
        }
      }
      --l;
      continue;
    }
    if (skip) {
      prevAbove = false;
    } else if (solvePatch(surf, r, pos[0], pos[1], t, tOut, prevAbove, tHit, &s)) {
      return true;
    }
    if (tOut >= t1) return false;
    t = tOut;
    const int a = tx[0] <= tx[1] ? 0 : 1, b = 1 - a;  // the axis crossed, the other
    pos[a] = r.dS[a] > 0 ? (n[a] + 1) << l : (n[a] << l) - 1;
    if (pos[a] < 0 || pos[a] >= N[a]) return false;
    pos[b] = std::clamp(nodeIndex(r.S(b, t), r.dS[b]), n[b] << l, std::min(((n[b] + 1) << l) - 1, N[b] - 1));
    // Up as many levels as the crossed boundary is a node boundary of (a ray that left a node
    // at level l entered a new one at every level whose grid line this is), at most to the top.
    if (codes) {
      const int boundary = r.dS[a] > 0 ? pos[a] : pos[a] + 1;
      int up = l;
      while (up < top && ((boundary >> (up + 1)) << (up + 1)) == boundary) ++up;
      l = up;
    }
  }
}

}  // namespace

Levels levelsOf(int tileW, int tileH) {
  Levels lv;
  int w = tileW + 1, h = tileH + 1;
  for (;;) {
    lv.w[lv.count] = w;
    lv.h[lv.count] = h;
    lv.offset[lv.count] = lv.total;
    lv.total += uint64_t(w) * h;
    ++lv.count;
    if (w == 1 && h == 1) break;
    w = (w + 1) / 2;
    h = (h + 1) / 2;
  }
  return lv;
}

void buildCellPyramid(const PackReader& pack, const CellRecord& c, std::vector<uint16_t>& out) {
  const Levels lv = levelsOf(c.tileW, c.tileH);
  const size_t base = out.size();
  out.resize(base + 2 * lv.total, kNodeEmpty);
  uint16_t* codes = out.data() + base;
  const Surface surf(pack, c);
  for (int py = 0; py < lv.h[0]; ++py)
    for (int px = 0; px < lv.w[0]; ++px) {
      const Patch p = surf.patch(px, py);
      double top = -kInf, bottom = kInf;
      for (int q = 0; q < (p.mixed ? 4 : 1); ++q) {
        const double* h = p.piece[q].h;
        if (!p.piece[q].covered) continue;
        top = std::max({top, h[0], h[1], h[2], h[3]});
        bottom = std::min({bottom, h[0], h[1], h[2], h[3]});
      }
      uint16_t* node = codes + 2 * (uint64_t(py) * lv.w[0] + px);
      node[0] = top == -kInf ? kNodeEmpty : encodeUp(top, c.box[4], c.box[5]);
      node[1] = top == -kInf ? kNodeNoFloor : encodeDown(bottom, c.box[4], c.box[5]);
    }
  for (int l = 1; l < lv.count; ++l) {
    const uint16_t* below = codes + 2 * lv.offset[l - 1];
    uint16_t* here = codes + 2 * lv.offset[l];
    for (int y = 0; y < lv.h[l]; ++y)
      for (int x = 0; x < lv.w[l]; ++x) {
        uint16_t top = kNodeEmpty, bottom = kNodeNoFloor;
        for (int k = 0; k < 4; ++k) {
          const int bx = 2 * x + (k & 1), by = 2 * y + (k >> 1);
          if (bx >= lv.w[l - 1] || by >= lv.h[l - 1]) continue;
          const uint16_t* child = below + 2 * (uint64_t(by) * lv.w[l - 1] + bx);
          top = std::max(top, child[0]);
          bottom = std::min(bottom, child[1]);
        }
        here[2 * (uint64_t(y) * lv.w[l] + x)] = top;
        here[2 * (uint64_t(y) * lv.w[l] + x) + 1] = bottom;
      }
  }
}

Pyramids buildPyramids(const PackReader& pack) {
  Pyramids p;
  auto cells = pack.cells();
  p.offsets.reserve(cells.size());
  for (const CellRecord& c : cells) {
    p.offsets.push_back(p.codes.size());
    buildCellPyramid(pack, c, p.codes);
  }
  return p;
}

ExtraSection bakeSection(const PackReader& pack, double* seconds) {
  const auto t0 = std::chrono::steady_clock::now();
  const Pyramids p = buildPyramids(pack);
  SectionHeader h{};
  h.version = kSectionVersion;
  h.cellCount = uint32_t(p.offsets.size());
  h.codeCount = p.codes.size();
  h.bakeSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (seconds) *seconds = h.bakeSeconds;
  ExtraSection s;
  std::memcpy(s.id, kSectionId, 4);
  s.bytes.resize(sizeof(h) + p.offsets.size() * 8 + p.codes.size() * 2);
  std::memcpy(s.bytes.data(), &h, sizeof(h));
  std::memcpy(s.bytes.data() + sizeof(h), p.offsets.data(), p.offsets.size() * 8);
  std::memcpy(s.bytes.data() + sizeof(h) + p.offsets.size() * 8, p.codes.data(), p.codes.size() * 2);
  return s;
}

Result<SectionView> readSection(const PackReader& pack) {
  const std::span<const uint8_t> b = pack.section(kSectionId);
  SectionView v;
  if (b.empty()) return v;
  const std::string where = pack.path() + ": section XMAX (the exact mode's maxima): ";
  SectionHeader h;
  if (b.size() < sizeof(h)) return Status::badInput(where + "too short");
  std::memcpy(&h, b.data(), sizeof(h));
  if (h.version != kSectionVersion)
    return Status::badInput(where + "version " + std::to_string(h.version) + ", this program reads version " +
                            std::to_string(kSectionVersion) + "; bake it again: scanatlas bake PACK --mode exact");
  const uint64_t cells = pack.cells().size();
  if (h.cellCount != cells) return Status::badInput(where + "made for another cell table (bake it again)");
  if (h.codeCount > b.size() / 2 || sizeof(h) + cells * 8 + h.codeCount * 2 != b.size())
    return Status::badInput(where + "its size does not match its header");
  v.present = true;
  v.bakeSeconds = h.bakeSeconds;
  v.offsets = reinterpret_cast<const uint64_t*>(b.data() + sizeof(h));
  v.codes = reinterpret_cast<const uint16_t*>(b.data() + sizeof(h) + cells * 8);
  v.codeCount = h.codeCount;
  v.bytes = b.size();
  for (uint64_t i = 0; i < cells; ++i) {
    const CellRecord& c = pack.cells()[i];
    const uint64_t need = 2 * levelsOf(c.tileW, c.tileH).total;
    if (v.offsets[i] % 2 || v.offsets[i] > h.codeCount || need > h.codeCount - v.offsets[i])
      return Status::badInput(where + "cell " + std::to_string(i) + "'s pyramid lies outside the section");
  }
  return v;
}

bool traceCell(const PackReader& pack, const CellRecord& c, const uint16_t* codes, const Eigen::Vector3d& o,
               const Eigen::Vector3d& d, double t0, double t1, double& tHit, TraceStats* stats) {
  return trace(pack, c, codes, o, d, t0, t1, tHit, stats);
}

double surfaceHeight(const PackReader& pack, const CellRecord& c, double u, double v) {
  const Surface surf(pack, c);
  const double S[2] = {std::clamp((u - c.box[0]) / (c.box[1] - c.box[0]) * c.tileW, 0.0, double(c.tileW)) + 0.5,
                       std::clamp((v - c.box[2]) / (c.box[3] - c.box[2]) * c.tileH, 0.0, double(c.tileH)) + 0.5};
  const int px = std::min(int(std::floor(S[0])), int(c.tileW)), py = std::min(int(std::floor(S[1])), int(c.tileH));
  const double ax = S[0] - px, ay = S[1] - py;
  const Patch p = surf.patch(px, py);
  const Piece& pc = p.piece[p.mixed ? (ax >= 0.5 ? 1 : 0) + (ay >= 0.5 ? 2 : 0) : 0];
  if (!pc.covered) return std::numeric_limits<double>::quiet_NaN();
  return (pc.h[0] * (1 - ax) + pc.h[1] * ax) * (1 - ay) + (pc.h[2] * (1 - ax) + pc.h[3] * ax) * ay;
}

bool traceCellLinear(const PackReader& pack, const CellRecord& c, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                     double t0, double t1, double& tHit) {
  TraceStats st;
  return trace(pack, c, nullptr, o, d, t0, t1, tHit, &st) && !st.capped;
}

}  // namespace sa::exact
