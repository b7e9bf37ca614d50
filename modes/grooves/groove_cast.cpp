#include "modes/grooves/groove_cast.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include <Eigen/Dense>

#include <zstd.h>

#include "atlas/zstd_context.h"
#include "modes/exact/exact.h"

namespace sa::gcast {
namespace {

Eigen::Vector3d toFrame(const CellRecord& c, const Eigen::Vector3d& p) {
  const Eigen::Vector3d r = p - Eigen::Vector3d(c.origin);
  return {r.dot(Eigen::Vector3d(c.u)), r.dot(Eigen::Vector3d(c.v)), r.dot(Eigen::Vector3d(c.w))};
}

double texelOf(const CellRecord& c) {
  return std::min((c.box[1] - c.box[0]) / c.tileW, (c.box[3] - c.box[2]) / c.tileH);
}

Eigen::Vector2d across(const Piece& p) { return {-p.e.y(), p.e.x()}; }

// ceil(x) clamped to 1..4096, in double first (a huge or NaN x must not overflow the conversion).
int countOf(double x) { return x >= 1 ? (x < 4096 ? int(std::ceil(x)) : 4096) : 1; }

int gridOf(const CellRecord& c) { return std::clamp(int(std::ceil(std::max(c.tileW, c.tileH) / 4.0)), 1, kMaxGrid); }

// The bin of (u, v) in a cell's grid (clamped to the grid).
int binCoord(double x, double lo, double hi, int g) {
  // Clamped in double first: a far point (or NaN) must not overflow the conversion.
  const double f = std::floor((x - lo) / (hi - lo) * g);
  return f >= 0 ? (f < g ? int(f) : g - 1) : 0;
}

// Piece p's rim: at each end a parabola across the line, least squares over the height field on
// both sides, from the lips (half a width plus a texel from the line; for packs made from points
// two sample spacings more, past the reach of the reconstruction's blur of the crack) 4 texels
// outward, at 3 places along (5 x 3 samples a side: scan noise averages out). With one side
// uncovered, a straight line from the other; with neither, level at the line's own height (wA,
// wB: the line lies at the rim level). nEnd: the direction across at each end (at a bend of the
// polyline the bisector, so the pieces on either side fit the same parabola and meet there).
void measureRim(const PackReader& pack, const CellRecord& c, Piece& p, double wA, double wB, const Eigen::Vector2d nEnd[2]) {
  const bool points = (pack.meta().flags & kPackFromTriangles) == 0;
  const double texel = texelOf(c);
  p.lip = p.halfWidth + texel + (points ? 2 * pack.meta().sampleSpacing : 0.0);
  for (int end = 0; end < 2; ++end) {
    const Eigen::Vector2d q = p.a + p.e * (end ? p.length : 0.0), n = nEnd[end];
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    int count[2] = {0, 0};
    for (int side = 0; side < 2; ++side)
      for (int along = -1; along <= 1; ++along)
        for (int k = 0; k <= 4; ++k) {
          const double x = (side ? 1 : -1) * (p.lip + k * texel);
          const Eigen::Vector2d l = q + p.e * (along * texel) + n * x;
          const double h = exact::surfaceHeight(pack, c, l.x(), l.y());
          if (std::isnan(h)) continue;
          const double xs = x / p.lip;  // scaled: the normal equations stay well conditioned
          const Eigen::Vector3d v(1, xs, xs * xs);
          A += v * v.transpose();
          b += v * h;
          ++count[side];
        }
    double* r = p.rimQ[end];
    const int fitted = (count[0] >= 5 && count[1] >= 5) ? 3 : (count[0] + count[1] >= 5 ? 2 : 0);
    Eigen::Vector3d co = Eigen::Vector3d::Zero();
    if (fitted == 3) co = A.ldlt().solve(b);
    else if (fitted == 2) co.head<2>() = A.topLeftCorner<2, 2>().ldlt().solve(b.head<2>());
    if (fitted == 0 || !co.allFinite()) co = Eigen::Vector3d(end ? wB : wA, 0, 0);
    r[0] = co[0];
    r[1] = co[1] / p.lip;
    r[2] = co[2] / (p.lip * p.lip);
  }
}

// Whether the groove's segment A-B (frame) lies on cell c's surface: at one of a few points along
// it inside the box, the height field is covered and within the groove's depth plus two texels.
bool onSurface(const PackReader& pack, const CellRecord& c, const Eigen::Vector3d& A, const Eigen::Vector3d& B, double depth) {
  const double tol = depth + 2 * texelOf(c);
  for (int k = 0; k <= 8; ++k) {
    const Eigen::Vector3d q = A + (B - A) * (k / 8.0);
    if (q.x() < c.box[0] || q.x() > c.box[1] || q.y() < c.box[2] || q.y() > c.box[3]) continue;
    const double h = exact::surfaceHeight(pack, c, q.x(), q.y());
    if (!std::isnan(h) && std::abs(h - q.z()) <= tol) return true;
  }
  return false;
}

// The lowest point of piece p's floor over its capsule: the rim is linear in s for each x, so its
// least over the capsule's s range (a lip past either end) is at one end of that range: the
// lower of those two parabolas' minima over x in [-lip, lip], less the profile's deepest sample.
double lowestFloor(const Piece& p, const float* profile) {
  double low = std::numeric_limits<double>::infinity();
  const double e = p.length > 0 ? p.lip / p.length : 0.0;
  for (int end = 0; end < 2; ++end) {
    const double* a = p.rimQ[end];
    const double* b = p.rimQ[1 - end];
    const double q[3] = {(1 + e) * a[0] - e * b[0], (1 + e) * a[1] - e * b[1], (1 + e) * a[2] - e * b[2]};
    auto at = [&](double x) { return q[0] + q[1] * x + q[2] * x * x; };
    low = std::min({low, at(-p.lip), at(p.lip)});
    if (q[2] > 0 && std::abs(q[1] / (2 * q[2])) < p.lip) low = std::min(low, at(-q[1] / (2 * q[2])));
  }
  return low - *std::max_element(profile, profile + kProfileSamples);
}

// How far piece p's floor rises above the height field over its capsule (samples half a texel
// apart; rises under a twentieth of a texel count as none).
double riseOver(const PackReader& pack, const CellRecord& c, const Model& m, const Piece& p) {
  const HeightField h{&pack, &c};
  const double step = 0.5 * texelOf(c);
  const int ns = countOf((p.length + 2 * p.lip) / step), nx = countOf(2 * p.lip / step);
  double rise = 0;
  for (int i = 0; i <= ns; ++i)
    for (int j = 0; j <= nx; ++j) {
      const Eigen::Vector2d q = p.a + p.e * (-p.lip + (p.length + 2 * p.lip) * i / ns) + across(p) * (-p.lip + 2 * p.lip * j / nx);
      double s, x;
      if (pieceDistance(p, q, s, x) >= p.lip) continue;
      const double hq = h(q.x(), q.y());
      if (!std::isnan(hq)) rise = std::max(rise, pieceFloor(m, h, p, q) - hq);
    }
  return rise > 0.05 * texelOf(c) ? rise : 0.0;
}

void binPieces(const CellRecord& c, CellPieces& cp) {
  const int g = cp.grid = gridOf(c);
  cp.bins.assign(size_t(g) * g, {});
  for (uint32_t i = 0; i < cp.pieces.size(); ++i) {
    const Piece& p = cp.pieces[i];
    const Eigen::Vector2d b = p.a + p.e * p.length;
    const Eigen::Vector2d lo = p.a.cwiseMin(b).array() - p.lip, hi = p.a.cwiseMax(b).array() + p.lip;
    const int x0 = binCoord(lo.x(), c.box[0], c.box[1], g), x1 = binCoord(hi.x(), c.box[0], c.box[1], g);
    const int y0 = binCoord(lo.y(), c.box[2], c.box[3], g), y1 = binCoord(hi.y(), c.box[2], c.box[3], g);
    // Only bins the capsule reaches: the bin's centre within the half width plus half the bin's
    // diagonal of the segment (a long diagonal piece's box holds many bins it never touches).
    const double bw = (c.box[1] - c.box[0]) / g, bh = (c.box[3] - c.box[2]) / g, reach = p.lip + 0.5 * std::hypot(bw, bh);
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        const Eigen::Vector2d centre(c.box[0] + (x + 0.5) * bw, c.box[2] + (y + 0.5) * bh);
        double s, xx;
        if (pieceDistance(p, centre, s, xx) <= reach) cp.bins[size_t(y) * g + x].push_back(i);
      }
  }
}

}  // namespace

bool profileOf(const Groove& g, float out[kProfileSamples]) {
  if (g.shape == "gap" || !(g.width > 0)) return false;
  const double hw = 0.5 * g.width;
  if (g.profile.size() >= 3) {
    // Fold the measured cross-section over the centre line: per sample radius, the mean of the
    // two sides' linear interpolations (where a side has samples that far out).
    std::vector<std::pair<double, double>> side[2];
    for (const auto& [x, h] : g.profile) side[x >= 0 ? 1 : 0].push_back({std::abs(double(x)), -double(h)});  // stored as residuals: negative below the rim
    for (auto& s : side) std::sort(s.begin(), s.end());
    auto at = [&](const std::vector<std::pair<double, double>>& s, double r, double& v) {
      if (s.size() < 2 || r < s.front().first - 1e-9 * hw || r > s.back().first + 1e-9 * hw) return false;
      auto it = std::lower_bound(s.begin(), s.end(), std::make_pair(r, -std::numeric_limits<double>::infinity()));
      if (it == s.begin()) { v = it->second; return true; }
      if (it == s.end()) { v = s.back().second; return true; }
      const auto& [r1, h1] = *it;
      const auto& [r0, h0] = *(it - 1);
      v = r1 > r0 ? h0 + (h1 - h0) * (r - r0) / (r1 - r0) : h1;
      return true;
    };
    bool ok = true;
    for (int k = 0; k < kProfileSamples && ok; ++k) {
      const double r = hw * k / (kProfileSamples - 1);
      double sum = 0, v = 0;
      int n = 0;
      for (const auto& s : side)
        if (at(s, r, v)) sum += v, ++n;
      if (n == 0) ok = false;
      else out[k] = float(std::max(0.0, sum / n));
    }
    if (ok) {
      out[kProfileSamples - 1] = 0;
      return true;
    }
  }
  if (!(g.depth > 0)) return false;
  for (int k = 0; k < kProfileSamples; ++k) {
    const double f = double(k) / (kProfileSamples - 1);
    out[k] = float(g.shape == "U" ? g.depth * std::sqrt(std::max(0.0, 1 - f * f)) : g.depth * (1 - f));
  }
  out[kProfileSamples - 1] = 0;
  return true;
}

Model buildModel(const PackReader& pack, const GrooveSet& set) {
  Model m;
  const auto cells = pack.cells();
  m.cellIndex.assign(cells.size(), -1);
  const Eigen::Vector3d origin(pack.meta().origin);
  std::vector<CellPieces> per(cells.size());
  for (const Groove& g : set.grooves) {
    float prof[kProfileSamples];
    if (g.line.size() < 2 || !profileOf(g, prof)) {
      ++m.skipped;
      continue;
    }
    const uint32_t gi = m.grooves++;
    m.profiles.insert(m.profiles.end(), prof, prof + kProfileSamples);
    const double hw = 0.5 * g.width, depth = *std::max_element(prof, prof + kProfileSamples);
    bool placed = false;
    for (uint32_t ci = 0; ci < cells.size(); ++ci) {
      const CellRecord& c = cells[ci];
      const double pad = hw + depth + 2 * texelOf(c);
      for (size_t k = 0; k + 1 < g.line.size(); ++k) {
        const Eigen::Vector3d A = toFrame(c, g.line[k] - origin), B = toFrame(c, g.line[k + 1] - origin);
        const Eigen::Vector3d lo = A.cwiseMin(B), hi = A.cwiseMax(B);
        if (hi.x() < c.box[0] - hw || lo.x() > c.box[1] + hw || hi.y() < c.box[2] - hw || lo.y() > c.box[3] + hw ||
            hi.z() < c.box[4] - pad || lo.z() > c.box[5] + pad)
          continue;
        if (!onSurface(pack, c, A, B, depth)) continue;
        // Across at the segment's ends: the bisector with the neighbouring segment's at a bend.
        auto acrossOf = [&](size_t i) {
          const Eigen::Vector2d d = (toFrame(c, g.line[i + 1] - origin) - toFrame(c, g.line[i] - origin)).head<2>();
          return d.norm() > 1e-12 ? Eigen::Vector2d(-d.y() / d.norm(), d.x() / d.norm()) : Eigen::Vector2d(0, 0);
        };
        const Eigen::Vector2d nk = acrossOf(k);
        auto bisector = [&](const Eigen::Vector2d& other) {
          const Eigen::Vector2d b = nk + other;
          return b.norm() > 0.5 ? Eigen::Vector2d(b.normalized()) : nk;
        };
        const Eigen::Vector2d nA = k > 0 ? bisector(acrossOf(k - 1)) : nk, nB = k + 2 < g.line.size() ? bisector(acrossOf(k + 1)) : nk;
        // Pieces of at most kMaxPieceTexels, so the lips follow the surface.
        const int parts = countOf((B - A).head<2>().norm() / (kMaxPieceTexels * texelOf(c)));
        for (int k2 = 0; k2 < parts; ++k2) {
          const Eigen::Vector3d P = A + (B - A) * (double(k2) / parts), Q = A + (B - A) * (double(k2 + 1) / parts);
          Piece p;
          p.a = P.head<2>();
          const Eigen::Vector2d ab = Q.head<2>() - P.head<2>();
          p.length = ab.norm();
          p.e = p.length > 1e-12 ? Eigen::Vector2d(ab / p.length) : Eigen::Vector2d::UnitX();
          p.halfWidth = hw;
          p.groove = gi;
          const Eigen::Vector2d ends[2] = {k2 == 0 ? nA : across(p), k2 + 1 == parts ? nB : across(p)};
          measureRim(pack, c, p, P.z(), Q.z(), ends);
          per[ci].pieces.push_back(p);
        }
        placed = true;
      }
    }
    if (placed) ++m.drawn;
    else ++m.skipped;
  }
  for (uint32_t ci = 0; ci < cells.size(); ++ci) {
    if (per[ci].pieces.empty()) continue;
    per[ci].cell = ci;
    per[ci].floor = cells[ci].box[4];
    for (const Piece& p : per[ci].pieces) {
      const float* prof = &m.profiles[size_t(p.groove) * kProfileSamples];
      per[ci].floor = std::min({per[ci].floor, lowestFloor(p, prof), cells[ci].box[4] - *std::max_element(prof, prof + kProfileSamples)});
      per[ci].rise = std::max(per[ci].rise, riseOver(pack, cells[ci], m, p));
    }
    binPieces(cells[ci], per[ci]);
    m.cellIndex[ci] = int32_t(m.cells.size());
    m.cells.push_back(std::move(per[ci]));
  }
  return m;
}

ExtraSection makeSection(const PackReader& pack, const Model& m, const std::string& json, double bakeSeconds) {
  const uint32_t cellCount = uint32_t(pack.cells().size());
  std::vector<uint32_t> entries(cellCount, kNoEntry), words;
  auto put = [&](float f) {
    uint32_t u;
    std::memcpy(&u, &f, 4);
    words.push_back(u);
  };
  for (float f : m.profiles) put(f);
  uint32_t pieces = 0;
  for (const CellPieces& cp : m.cells) {
    entries[cp.cell] = uint32_t(words.size());
    const size_t blk = words.size();
    const uint32_t g = uint32_t(cp.grid), maskWords = binMaskWords(g);
    uint32_t listLen = 0, held = 0;
    for (const auto& b : cp.bins) listLen += uint32_t(b.size()), held += !b.empty();
    const uint32_t listOff = kBlockHeaderWords + 2 * maskWords + held + 1, pieceOff = listOff + listLen;
    words.insert(words.end(), {g, uint32_t(cp.pieces.size()), listOff, pieceOff});
    put(float(cp.floor) - 1e-6f * std::max(1.0f, std::abs(float(cp.floor))));
    put(float(cp.rise));
    // Sparse bins: which hold pieces (bit k of word k / 32), the held bins before each mask word,
    // and each held bin's first entry in the lists (one more: the end of the last).
    const size_t mask = words.size();
    words.resize(words.size() + 2 * maskWords, 0);
    for (size_t k = 0; k < cp.bins.size(); ++k)
      if (!cp.bins[k].empty()) words[mask + k / 32] |= 1u << (k % 32);
    for (uint32_t w = 0, before = 0; w < maskWords; ++w) {
      words[mask + maskWords + w] = before;
      before += uint32_t(std::popcount(words[mask + w]));
    }
    uint32_t start = 0;
    for (const auto& b : cp.bins)
      if (!b.empty()) words.push_back(start), start += uint32_t(b.size());
    words.push_back(start);
    for (const auto& b : cp.bins) words.insert(words.end(), b.begin(), b.end());
    for (const Piece& p : cp.pieces) {
      for (double v : {p.a.x(), p.a.y(), p.e.x(), p.e.y(), p.length, p.halfWidth, p.rimQ[0][0], p.rimQ[0][1], p.rimQ[0][2],
                       p.rimQ[1][0], p.rimQ[1][1], p.rimQ[1][2]})
        put(float(v));
      words.push_back(p.groove * kProfileSamples);
      put(float(p.lip));
    }
    pieces += uint32_t(cp.pieces.size());
    (void)blk;
  }
  SectionHeader h{};
  h.version = kSectionVersion;
  h.cellCount = cellCount;
  h.grooveCount = m.grooves;
  h.pieceCount = pieces;
  h.bakeSeconds = bakeSeconds;
  h.wordCount = words.size();
  // The JSON (only the window's list and `info` read it) zstd-compressed: it was half the section.
  std::string packed(ZSTD_compressBound(json.size()), '\0');
  const size_t jz = ZSTD_compressCCtx(threadZstd().c, packed.data(), packed.size(), json.data(), json.size(), kJsonZstdLevel);
  if (ZSTD_isError(jz) || json.empty() || json.size() > kMaxJsonBytesPerGroove * (uint64_t(m.grooves) + 16)) {
    packed = json;  // stored as it is (a bound-sized buffer fails only for want of memory; past the
                    // readers' bound on a stated size, it is read as the bytes that are there)
    h.jsonRawBytes = 0;
  } else {
    packed.resize(jz);
    h.jsonRawBytes = uint32_t(json.size());
  }
  h.jsonBytes = packed.size();
  h.profileSamples = kProfileSamples;
  ExtraSection s;
  std::memcpy(s.id, kSectionId, 4);
  s.bytes.resize(sizeof(h) + entries.size() * 4 + words.size() * 4 + packed.size());
  uint8_t* o = s.bytes.data();
  std::memcpy(o, &h, sizeof(h));
  std::memcpy(o + sizeof(h), entries.data(), entries.size() * 4);
  if (!words.empty()) std::memcpy(o + sizeof(h) + entries.size() * 4, words.data(), words.size() * 4);
  std::memcpy(o + sizeof(h) + (entries.size() + words.size()) * 4, packed.data(), packed.size());
  return s;
}

Result<SectionView> readSection(const PackReader& pack) {
  SectionView v;
  const auto bytes = pack.section(kSectionId);
  if (bytes.empty()) return v;
  const std::string where = pack.path() + ": section GROO: ";
  if (bytes.size() < sizeof(SectionHeader)) return Status::badInput(where + "shorter than its header");
  std::memcpy(&v.header, bytes.data(), sizeof(SectionHeader));
  const SectionHeader& h = v.header;
  if (h.version != kSectionVersion)
    return Status::badInput(where + "version " + std::to_string(h.version) + " (this scanatlas reads " +
                            std::to_string(kSectionVersion) + "); bake it again: scanatlas bake PACK --mode grooves");
  if (h.cellCount != pack.cells().size()) return Status::badInput(where + "made for another cell table; bake it again");
  if (h.profileSamples != kProfileSamples) return Status::badInput(where + "profiles of " + std::to_string(h.profileSamples) + " samples");
  const uint64_t body = bytes.size() - sizeof(SectionHeader);
  if (h.wordCount > body / 4 || uint64_t(h.cellCount) * 4 > body - h.wordCount * 4 ||
      h.jsonBytes != body - h.wordCount * 4 - uint64_t(h.cellCount) * 4)
    return Status::badInput(where + "sizes do not add up to the section's " + std::to_string(bytes.size()) + " bytes");
  if (uint64_t(h.grooveCount) * kProfileSamples > h.wordCount) return Status::badInput(where + "profiles past its words");
  v.entries = reinterpret_cast<const uint32_t*>(bytes.data() + sizeof(SectionHeader));
  v.words = v.entries + h.cellCount;
  // Every block inside the words, with its bins, lists and pieces (the shader trusts them).
  const uint64_t W = h.wordCount;
  for (uint32_t i = 0; i < h.cellCount; ++i) {
    const uint32_t b = v.entries[i];
    if (b == kNoEntry) continue;
    const std::string cellWhere = where + "cell " + std::to_string(i);
    if (uint64_t(b) + kBlockHeaderWords > W) return Status::badInput(cellWhere + "'s block is past the words");
    const uint32_t g = v.words[b], n = v.words[b + 1], lo = v.words[b + 2], po = v.words[b + 3];
    if (g < 1 || g > kMaxGrid || po < lo || uint64_t(b) + po + uint64_t(n) * kPieceWords > W)
      return Status::badInput(cellWhere + "'s block is malformed");
    // The bins' mask, the counts before each of its words, the held bins' starts.
    const uint32_t M = binMaskWords(g);
    if (uint64_t(kBlockHeaderWords) + 2 * M + 1 > lo) return Status::badInput(cellWhere + "'s block is malformed");
    const uint32_t* mask = v.words + b + kBlockHeaderWords;
    uint32_t held = 0;
    for (uint32_t w = 0; w < M; ++w) {
      if (mask[M + w] != held) return Status::badInput(cellWhere + ": its bins' counts do not add up");
      held += uint32_t(std::popcount(mask[w]));
    }
    if ((g * g) % 32 && mask[M - 1] >> ((g * g) % 32)) return Status::badInput(cellWhere + ": a bin past its grid");
    if (lo != kBlockHeaderWords + 2 * M + held + 1) return Status::badInput(cellWhere + "'s block is malformed");
    const uint32_t* starts = mask + 2 * M;
    for (uint32_t k = 0; k < held; ++k)
      if (starts[k] > starts[k + 1]) return Status::badInput(cellWhere + ": a bin's list is malformed");
    if (held && (starts[0] != 0 || starts[held] > po - lo))
      return Status::badInput(cellWhere + ": a bin's list is past its block");
    for (uint32_t q = 0; held && q < starts[held]; ++q)
      if (v.words[b + lo + q] >= n) return Status::badInput(cellWhere + ": a bin names a piece it lacks");
    for (uint32_t q = 0; q < n; ++q)
      if (uint64_t(v.words[b + po + q * kPieceWords + 12]) + kProfileSamples > uint64_t(h.grooveCount) * kProfileSamples)
        return Status::badInput(cellWhere + ": a piece names a profile it lacks");
  }
  const char* json = reinterpret_cast<const char*>(v.words + W);
  if (h.jsonRawBytes == 0) {
    v.json.assign(json, h.jsonBytes);
  } else {
    // The stated size is checked against the frame's own, and against what the grooves stored
    // (whose profiles the words hold) can take, before anything that size is allocated.
    const unsigned long long framed = ZSTD_getFrameContentSize(json, h.jsonBytes);
    if (framed != h.jsonRawBytes || h.jsonRawBytes > kMaxJsonBytesPerGroove * (uint64_t(h.grooveCount) + 16))
      return Status::badInput(where + "its groove list is damaged (zstd frame of " + std::to_string(h.jsonRawBytes) + " bytes)");
    v.json.resize(h.jsonRawBytes);
    const size_t got = ZSTD_decompressDCtx(threadZstd().d, v.json.data(), v.json.size(), json, h.jsonBytes);
    if (ZSTD_isError(got) || got != h.jsonRawBytes) return Status::badInput(where + "its groove list is damaged (zstd)");
  }
  v.present = true;
  v.bytes = bytes.size();
  return v;
}

float blockRise(const SectionView& v, uint32_t cell) {
  if (!v.present || cell >= v.header.cellCount || v.entries[cell] == kNoEntry) return 0;
  float rise;
  std::memcpy(&rise, &v.words[v.entries[cell] + 5], 4);
  return rise;
}

Model modelFromSection(const PackReader& pack, const SectionView& v) {
  Model m;
  if (!v.present) return m;
  auto f = [&](uint64_t w) {
    float x;
    std::memcpy(&x, &v.words[w], 4);
    return double(x);
  };
  m.grooves = v.header.grooveCount;
  for (uint64_t k = 0; k < uint64_t(m.grooves) * kProfileSamples; ++k) m.profiles.push_back(float(f(k)));
  m.cellIndex.assign(pack.cells().size(), -1);
  for (uint32_t i = 0; i < v.header.cellCount; ++i) {
    const uint32_t b = v.entries[i];
    if (b == kNoEntry) continue;
    CellPieces cp;
    cp.cell = i;
    cp.grid = int(v.words[b]);
    const uint32_t n = v.words[b + 1], lo = v.words[b + 2], po = v.words[b + 3];
    cp.floor = f(b + 4);
    cp.rise = blockRise(v, i);
    cp.bins.resize(size_t(cp.grid) * cp.grid);
    const uint32_t* mask = v.words + b + kBlockHeaderWords;
    const uint32_t* starts = mask + 2 * binMaskWords(uint32_t(cp.grid));
    for (size_t k = 0, held = 0; k < cp.bins.size(); ++k)
      if (mask[k / 32] >> (k % 32) & 1u) {
        cp.bins[k].assign(v.words + b + lo + starts[held], v.words + b + lo + starts[held + 1]);
        ++held;
      }
    for (uint32_t q = 0; q < n; ++q) {
      const uint64_t w = uint64_t(b) + po + uint64_t(q) * kPieceWords;
      Piece p;
      p.a = {f(w), f(w + 1)};
      p.e = {f(w + 2), f(w + 3)};
      p.length = f(w + 4);
      p.halfWidth = f(w + 5);
      for (int e = 0; e < 2; ++e)
        for (int k = 0; k < 3; ++k) p.rimQ[e][k] = f(w + 6 + 3 * e + k);
      p.groove = v.words[w + 12] / kProfileSamples;
      p.lip = f(w + 13);
      cp.pieces.push_back(p);
    }
    m.cellIndex[i] = int32_t(m.cells.size());
    m.cells.push_back(std::move(cp));
  }
  return m;
}

// --- the cast ---

double pieceDistance(const Piece& p, const Eigen::Vector2d& q, double& s, double& x) {
  const Eigen::Vector2d r = q - p.a;
  s = r.dot(p.e);
  x = r.dot(across(p));
  const double sc = std::clamp(s, 0.0, p.length);
  return (r - p.e * sc).norm();
}

double profileDepth(const float* profile, double r, double halfWidth, double* slope) {
  if (slope) *slope = 0;
  if (!(r < halfWidth)) return 0;
  const double f = std::max(r, 0.0) / halfWidth * (kProfileSamples - 1);
  const int k = std::min(int(f), kProfileSamples - 2);
  const double a = f - k, d0 = profile[k], d1 = profile[k + 1];
  if (slope) *slope = (d1 - d0) * (kProfileSamples - 1) / halfWidth;
  return d0 + (d1 - d0) * a;
}

double HeightField::operator()(double u, double v) const { return exact::surfaceHeight(*pack, *cell, u, v); }
double HeightField::texel() const { return texelOf(*cell); }

double pieceRim(const Piece& p, double s, double x, Eigen::Vector2d* gradient) {
  // Along, linear between the ends and on past them (the rounded ends follow the surface's slope
  // along the line, as the sides follow it across).
  const double fs = p.length > 0 ? s / p.length : 0.0;
  const double xc = std::clamp(x, -p.lip, p.lip);
  const double* q0 = p.rimQ[0];
  const double* q1 = p.rimQ[1];
  const double r0 = q0[0] + q0[1] * xc + q0[2] * xc * xc, r1 = q1[0] + q1[1] * xc + q1[2] * xc * xc;
  if (gradient) {
    const double dx0 = q0[1] + 2 * q0[2] * xc, dx1 = q1[1] + 2 * q1[2] * xc;
    *gradient = std::abs(x) < p.lip ? Eigen::Vector2d(across(p) * (dx0 + (dx1 - dx0) * fs)) : Eigen::Vector2d::Zero();
    if (p.length > 0) *gradient += p.e * ((r1 - r0) / p.length);
  }
  return r0 + (r1 - r0) * fs;
}

double smoothSlope(const float* profile, double r, double halfWidth) {
  if (!(r < halfWidth)) return 0;
  const int n = kProfileSamples - 1;
  auto facet = [&](int k) { return (double(profile[k + 1]) - profile[k]) * n / halfWidth; };
  const double f = std::max(r, 0.0) / halfWidth * n - 0.5;  // facet centres at integers
  if (f <= 0) return facet(0);
  if (f >= n - 1) return facet(n - 1);
  const int k = int(f);
  return facet(k) + (facet(k + 1) - facet(k)) * (f - k);
}

double pieceFloor(const Model& m, const HeightField& h, const Piece& p, const Eigen::Vector2d& q, Eigen::Vector2d* gradient) {
  double s, x;
  const double r = pieceDistance(p, q, s, x);
  double slope = 0;
  const float* profile = &m.profiles[size_t(p.groove) * kProfileSamples];
  const double D = profileDepth(profile, r, p.halfWidth, &slope);
  Eigen::Vector2d g;
  const double rim = pieceRim(p, s, x, &g);
  if (gradient) {
    if (r > 0 && r < p.halfWidth) {
      const Eigen::Vector2d c = p.a + p.e * std::clamp(s, 0.0, p.length);
      g -= smoothSlope(profile, r, p.halfWidth) * (q - c) / r;
    }
    *gradient = g;
  }
  (void)h;
  return rim - D;
}

namespace {

// Where the 2-D line q + t dq (at t, inside the capsule) leaves piece p's capsule.
// Where the 2-D line q + t dq meets piece p's capsule (out to its lips): entry, exit (entry >= exit
// when it misses).
std::pair<double, double> capsuleSpan(const Piece& p, const Eigen::Vector2d& q, const Eigen::Vector2d& dq) {
  const double inf = std::numeric_limits<double>::infinity();
  const double hw = p.lip;
  double entry = inf, exit = -inf;
  // The body: s in [0, L], |x| < lip.
  const Eigen::Vector2d n = across(p);
  const double s0 = (q - p.a).dot(p.e), sd = dq.dot(p.e), x0 = (q - p.a).dot(n), xd = dq.dot(n);
  auto slab = [&](double v0, double vd, double lo, double hi, double& tin, double& tout) {
    if (std::abs(vd) < 1e-300) {
      if (v0 < lo || v0 > hi) tin = inf, tout = -inf;
      return;
    }
    double a = (lo - v0) / vd, b = (hi - v0) / vd;
    if (a > b) std::swap(a, b);
    tin = std::max(tin, a);
    tout = std::min(tout, b);
  };
  double tin = -inf, tout = inf;
  slab(s0, sd, 0, p.length, tin, tout);
  slab(x0, xd, -hw, hw, tin, tout);
  if (tin < tout) entry = std::min(entry, tin), exit = std::max(exit, tout);
  for (const Eigen::Vector2d& c : {p.a, Eigen::Vector2d(p.a + p.e * p.length)}) {
    const Eigen::Vector2d r = q - c;
    const double A = dq.squaredNorm(), B = r.dot(dq), C = r.squaredNorm() - hw * hw;
    if (A < 1e-300) {
      if (C < 0) entry = -inf, exit = inf;
      continue;
    }
    const double disc = B * B - A * C;
    if (disc <= 0) continue;
    entry = std::min(entry, (-B - std::sqrt(disc)) / A);
    exit = std::max(exit, (-B + std::sqrt(disc)) / A);
  }
  return {entry, exit};
}

// Where the 2-D line q + t dq (at t, inside the capsule) leaves piece p's capsule.
double capsuleExit(const Piece& p, const Eigen::Vector2d& q, const Eigen::Vector2d& dq, double t) {
  return t + std::max(capsuleSpan(p, q, dq).second, 0.0);
}

}  // namespace

double airExit(const Model& m, const HeightField& h, const Piece& p, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
               double t, double t1) {
  const Eigen::Vector3d q0 = o + d * t;
  const double te = capsuleExit(p, q0.head<2>(), d.head<2>(), 0.0) + t;
  const double tEnd = std::min(te, t1);
  auto f = [&](double tt) {
    const Eigen::Vector3d q = o + d * tt;
    return q.z() - pieceFloor(m, h, p, q.head<2>());
  };
  constexpr int kSteps = 16;
  double ta = t, fa = f(t);
  for (int i = 1; i <= kSteps; ++i) {
    double tb = t + (tEnd - t) * i / kSteps, fb = f(tb);
    if (fb <= 0) {
      for (int k = 0; k < 20; ++k) {
        const double tm = 0.5 * (ta + tb), fm = f(tm);
        if (fm > 0) ta = tm, fa = fm;
        else tb = tm, fb = fm;
      }
      const double ts = fa > fb ? ta + (tb - ta) * fa / (fa - fb) : tb;
      return f(ts) <= 0 ? ts : tb;
    }
    ta = tb;
    fa = fb;
  }
  // Out of the capsule (a hair past its edge, so the point is outside) or at the box's end.
  return te < t1 ? te + 1e-9 * std::max(1.0, std::abs(te)) + 1e-6 * p.halfWidth : t1;
}

bool cover(const Model& m, const HeightField& h, const CellPieces& cp, const Eigen::Vector3d& q, int& air, int& lowest) {
  const CellRecord& c = *h.cell;
  const int g = cp.grid;
  const int bx = binCoord(q.x(), c.box[0], c.box[1], g), by = binCoord(q.y(), c.box[2], c.box[3], g);
  air = lowest = -1;
  double low = std::numeric_limits<double>::infinity();
  for (uint32_t i : cp.bins[size_t(by) * g + bx]) {
    const Piece& p = cp.pieces[i];
    double s, x;
    if (pieceDistance(p, q.head<2>(), s, x) >= p.lip) continue;
    const double f = pieceFloor(m, h, p, q.head<2>());
    if (q.z() > f) air = int(i);
    if (f < low) low = f, lowest = int(i);
  }
  return lowest >= 0;
}

double floorCrossing(const Model& m, const HeightField& h, const Piece& p, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                     double t0, double t1) {
  const auto [en, ex] = capsuleSpan(p, o.head<2>(), d.head<2>());
  const double a = std::max(t0, en), b = std::min(t1, ex);
  if (!(a < b)) return -1;
  const Eigen::Vector3d qa = o + d * a;
  if (qa.z() <= pieceFloor(m, h, p, qa.head<2>())) return a;
  const double te = airExit(m, h, p, o, d, a, b);
  const Eigen::Vector3d qe = o + d * te;
  double s, x;
  return te < b && pieceDistance(p, qe.head<2>(), s, x) < p.lip && qe.z() <= pieceFloor(m, h, p, qe.head<2>()) ? te : -1;
}

bool castGrooved(const PackReader& pack, const CellRecord& c, const Model& m, uint32_t cell, const Eigen::Vector3d& o,
                 const Eigen::Vector3d& d, double t0, double t1, CastResult& out) {
  const CellPieces* cp = m.find(cell);
  out = CastResult{};
  if (!cp) {
    double th;
    if (!exact::traceCellLinear(pack, c, o, d, t0, t1, th)) return false;
    out.t = th;
    return true;
  }
  const double eps = 1e-3 * texelOf(c);
  const HeightField hf{&pack, &c};
  // Before h's hit the ray is above h; a floor rises above h by at most cp->rise.
  const double window = 1.25 * cp->rise / std::max(std::abs(d.z()), 0.02);
  double t = t0;
  int piece = -1, air, lowest;
  bool found = false;
  for (uint32_t it = 0; it < 8 && !found; ++it) {
    out.iterations = it + 1;
    double th;
    const bool hh = exact::traceCellLinear(pack, c, o, d, t, t1, th);
    const double tH = hh ? th : t1;
    // A floor above the height field before tH: each piece near the stretch's ends (the bins hold
    // the pieces near them), its first floor crossing inside its capsule over the stretch.
    const double ta = std::max(t, tH - window);
    const double reach = d.head<2>().norm() * (tH - ta);
    double best = std::numeric_limits<double>::infinity();
    for (int e = 0; e < (cp->rise > 0 ? 2 : 0); ++e) {
      const Eigen::Vector3d qe = o + d * (e == 0 ? tH : ta);
      const int g = cp->grid;
      const int bx = binCoord(qe.x(), c.box[0], c.box[1], g), by = binCoord(qe.y(), c.box[2], c.box[3], g);
      for (uint32_t i : cp->bins[size_t(by) * g + bx]) {
        const Piece& p = cp->pieces[i];
        double s, x;
        if (pieceDistance(p, qe.head<2>(), s, x) >= p.lip + reach) continue;
        const double tc = floorCrossing(m, hf, p, o, d, ta, std::min(tH, best));
        if (tc >= 0) best = std::min(best, tc);
      }
    }
    if (best < tH) {
      t = best;  // on a floor: solid unless in another groove's air (the advance below goes on)
      if (cover(m, hf, *cp, o + d * t, air, lowest) && air < 0) {
        piece = lowest;
        found = true;
        break;
      }
    }
    if (found || (!hh && !(best < tH))) break;
    const bool fromFloor = best < tH;
    if (!fromFloor) t = tH;
    bool onward = false;
    for (int j = 0; j < 16; ++j) {
      const Eigen::Vector3d q = o + d * t;
      if (!cover(m, hf, *cp, q, air, lowest)) {
        const double h = hf(q.x(), q.y());
        if ((j == 0 && !fromFloor) || (!std::isnan(h) && q.z() <= h + eps)) found = true;
        else onward = true;
        break;
      }
      if (air < 0) {
        piece = lowest;
        found = true;
        break;
      }
      t = airExit(m, hf, cp->pieces[size_t(air)], o, d, t, t1);
      if (t >= t1) return false;
    }
    if (!found && !onward) found = true;
  }
  if (!found) return false;
  out.t = t;
  if (piece >= 0) {
    Eigen::Vector2d g;
    pieceFloor(m, hf, cp->pieces[size_t(piece)], (o + d * t).head<2>(), &g);
    out.piece = piece;
    out.normal = Eigen::Vector3d(-g.x(), -g.y(), 1).normalized();
  }
  return true;
}

double gapQuantum(const CellRecord& c) {
  const double tu = (c.box[1] - c.box[0]) / std::max<int>(c.tileW, 1), tv = (c.box[3] - c.box[2]) / std::max<int>(c.tileH, 1);
  return kGapFieldTexels * std::min(tu, tv) / 65535.0;
}

double widestAcross(const CellPieces& cp) {
  double wide = 0;
  for (const Piece& p : cp.pieces) {
    // The rim's slope across is bilinear in (position along, x): its extremes lie at the corners,
    // x at the lips, along from a piece length before the start to one past the end.
    double slope = 0;
    for (double fs : {-1.0, 2.0})
      for (double xc : {-p.lip, p.lip}) {
        const double d0 = p.rimQ[0][1] + 2 * p.rimQ[0][2] * xc, d1 = p.rimQ[1][1] + 2 * p.rimQ[1][2] * xc;
        slope = std::max(slope, std::abs(d0 + (d1 - d0) * (p.length > 0 ? fs : 0.0)));
      }
    wide = std::max(wide, 2 * p.halfWidth * std::sqrt(1 + slope * slope));
  }
  return wide * (1 + 1e-6);
}

// One cell's field: at each texel's centre the least (distance - lip) and (distance - half width)
// over the pieces within the cap's reach of it, less half the texel's diagonal (the bounds over its
// square: distance is 1-Lipschitz) and a thousandth of a texel (the shader's float arithmetic);
// and the two pieces of least (distance - half width) there (the anti-aliasing's candidates).
static void cellGapField(const CellRecord& c, const CellPieces& cp, uint32_t* out) {
  const int W = std::max<int>(c.tileW, 1), H = std::max<int>(c.tileH, 1);
  const double tu = (c.box[1] - c.box[0]) / W, tv = (c.box[3] - c.box[2]) / H;
  const double half = 0.5 * std::hypot(tu, tv), q = gapQuantum(c), cap = 65535.0 * q;
  std::vector<double> lip(size_t(W) * H, cap + half + 1), width(lip);
  std::vector<std::array<std::pair<double, uint32_t>, 2>> near(size_t(W) * H);
  for (auto& n : near) n.fill({std::numeric_limits<double>::infinity(), kNoEntry});
  for (uint32_t pi = 0; pi < cp.pieces.size(); ++pi) {
    const Piece& p = cp.pieces[pi];
    const Eigen::Vector2d b = p.a + p.e * p.length;
    const double r = std::max(p.lip, p.halfWidth) + cap + half;
    const int i0 = std::max(0, int(std::floor((std::min(p.a.x(), b.x()) - r - c.box[0]) / tu))),
              i1 = std::min(W - 1, int(std::ceil((std::max(p.a.x(), b.x()) + r - c.box[0]) / tu)));
    const int j0 = std::max(0, int(std::floor((std::min(p.a.y(), b.y()) - r - c.box[2]) / tv))),
              j1 = std::min(H - 1, int(std::ceil((std::max(p.a.y(), b.y()) + r - c.box[2]) / tv)));
    for (int j = j0; j <= j1; ++j)
      for (int i = i0; i <= i1; ++i) {
        double s, x;
        const Eigen::Vector2d ctr(c.box[0] + (i + 0.5) * tu, c.box[2] + (j + 0.5) * tv);
        const double d = pieceDistance(p, ctr, s, x);
        const size_t k = size_t(j) * W + i;
        lip[k] = std::min(lip[k], d - p.lip);
        width[k] = std::min(width[k], d - p.halfWidth);
        const std::pair<double, uint32_t> e(d - p.halfWidth, pi);
        if (e < near[k][0]) {
          near[k][1] = near[k][0];
          near[k][0] = e;
        } else if (e < near[k][1]) {
          near[k][1] = e;
        }
      }
  }
  // At the texel's centre: the shader takes off the distance from it (both are 1-Lipschitz). The
  // margin covers the shader's float rounding of the centre and the quantum.
  const double margin = 1e-3 * std::min(tu, tv);
  auto code = [&](double gap) {
    const double v = (gap - margin) / q;
    return v <= 0 ? 0u : v >= 65535 ? 65535u : uint32_t(std::floor(v));
  };
  const float wide = float(widestAcross(cp));
  std::memcpy(out, &wide, 4);
  for (size_t k = 0; k < lip.size(); ++k) {
    out[1 + kGapFieldWords * k] = code(lip[k]) | code(width[k]) << 16;
    out[1 + kGapFieldWords * k + 1] = near[k][0].second;
    out[1 + kGapFieldWords * k + 2] = near[k][1].second;
  }
}

std::vector<uint32_t> gapField(const PackReader& pack, const Model& m) {
  const auto cells = pack.cells();
  std::vector<uint32_t> words(cells.size(), kNoEntry);
  for (const CellPieces& cp : m.cells) {
    const CellRecord& c = cells[cp.cell];
    const size_t texels = size_t(std::max<int>(c.tileW, 1)) * std::max<int>(c.tileH, 1);
    words[cp.cell] = uint32_t(words.size());
    words.resize(words.size() + 1 + kGapFieldWords * texels, 0u);
    cellGapField(c, cp, words.data() + words[cp.cell]);
  }
  return words;
}

}  // namespace sa::gcast
