#include "modes/vdm/vdm.h"

#include <Eigen/Eigenvalues>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <mutex>
#include <cmath>
#include <numeric>
#include <random>

namespace sa::vdm {
namespace {

float half(double x) { return float(Eigen::half(float(x))); }  // what the section stores (fp16)

double texelOf(const CellRecord& c) { return std::min((c.box[1] - c.box[0]) / c.tileW, (c.box[3] - c.box[2]) / c.tileH); }

// Where o + t d leaves the cell's box (t >= 0).
double exitDistance(const CellRecord& c, const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
  double t1 = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0) continue;
    const double lo = c.box[2 * a], hi = c.box[2 * a + 1];
    t1 = std::min(t1, std::max((lo - o[a]) / d[a], (hi - o[a]) / d[a]));
  }
  return std::max(t1, 0.0);
}

Eigen::Vector2d texelCentre(const CellRecord& c, int i, int j) {
  return {c.box[0] + (i + 0.5) * (c.box[1] - c.box[0]) / c.tileW, c.box[2] + (j + 0.5) * (c.box[3] - c.box[2]) / c.tileH};
}

}  // namespace

double thetaOf(int i) { return kMaxThetaDeg * M_PI / 180 * i / (kThetas - 1); }
double phiOf(int j) { return 2 * M_PI * j / kPhis; }
Eigen::Vector3d direction(double theta, double phi) {
  return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), -std::cos(theta)};
}

double CellFunction::value(int texel, int dir) const {
  double v = mean[dir];
  const float* w = weights.data() + size_t(texel) * rank;
  for (int k = 0; k < rank; ++k) v += double(w[k]) * basis[size_t(k) * kDirs + dir];
  return v;
}

uint64_t CellFunction::bytes() const {
  return 2 * (mean.size() + basis.size() + weights.size()) + 4 * hitBits.size() + 16;
}

void sampleCell(const PackReader& pack, uint32_t cell, const uint16_t* pyramid, std::vector<float>& d,
                std::vector<uint8_t>& hit) {
  const CellRecord& c = pack.cells()[cell];
  const int n = int(c.tileW) * c.tileH;
  const double texel = texelOf(c);
  d.assign(size_t(n) * kDirs, 0.f);
  hit.assign(size_t(n) * kDirs, 0);
  Eigen::Vector3d dirs[kDirs];
  for (int i = 0; i < kThetas; ++i)
    for (int j = 0; j < kPhis; ++j) dirs[i * kPhis + j] = direction(thetaOf(i), phiOf(j));
  for (int y = 0; y < c.tileH; ++y)
    for (int x = 0; x < c.tileW; ++x) {
      const Eigen::Vector2d uv = texelCentre(c, x, y);
      const Eigen::Vector3d o(uv.x(), uv.y(), c.box[5]);
      const size_t row = size_t(y * c.tileW + x) * kDirs;
      for (int k = 0; k < kDirs; ++k) {
        const double t1 = exitDistance(c, o, dirs[k]);
        double t = 0;
        const bool h = exact::traceCell(pack, c, pyramid, o, dirs[k], 0, t1, t);
        d[row + k] = float((h ? t : t1) / texel);
        hit[row + k] = h;
      }
    }
}

CellFunction bakeCell(const PackReader& pack, uint32_t cell, const uint16_t* pyramid, const BakeOptions& opt) {
  const auto t0 = std::chrono::steady_clock::now();
  const CellRecord& c = pack.cells()[cell];
  CellFunction fn;
  fn.cell = cell;
  fn.tileW = c.tileW;
  fn.tileH = c.tileH;
  fn.texel = texelOf(c);
  std::vector<float> d;
  std::vector<uint8_t> hit;
  sampleCell(pack, cell, pyramid, d, hit);
  const int n = fn.tileW * fn.tileH;
  fn.hitBits.assign(size_t(n) * (kDirs / 32), 0);
  for (int r = 0; r < n; ++r)
    for (int k = 0; k < kDirs; ++k)
      if (hit[size_t(r) * kDirs + k]) fn.hitBits[size_t(r) * (kDirs / 32) + k / 32] |= 1u << (k % 32);
  const Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, kDirs, Eigen::RowMajor>> D(d.data(), n, kDirs);
  // The basis from at most 8192 rows (large tiles), the weights of every row.
  std::vector<int> rows(n);
  std::iota(rows.begin(), rows.end(), 0);
  if (n > 8192) {
    std::mt19937 rng(cell);
    std::shuffle(rows.begin(), rows.end(), rng);
    rows.resize(8192);
  }
  Eigen::Matrix<double, 1, kDirs> mean = Eigen::Matrix<double, 1, kDirs>::Zero();
  for (int r : rows) mean += D.row(r).cast<double>();
  mean /= double(rows.size());
  Eigen::MatrixXd X(rows.size(), kDirs);
  for (size_t i = 0; i < rows.size(); ++i) X.row(Eigen::Index(i)) = D.row(rows[i]).cast<double>() - mean;
  const Eigen::MatrixXd cov = X.transpose() * X;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(cov);
  const int kMax = std::min({opt.maxRank, kMaxRank, n});
  Eigen::MatrixXd E(kMax, kDirs);  // the largest eigenvalues' vectors first
  for (int k = 0; k < kMax; ++k) E.row(k) = eig.eigenvectors().col(kDirs - 1 - k).transpose();
  fn.mean.resize(kDirs);
  for (int k = 0; k < kDirs; ++k) fn.mean[k] = half(mean[k]);
  // Rank: the smallest k whose p95 error at hit samples (on the basis rows) is within tolerance.
  const Eigen::Map<const Eigen::Matrix<float, 1, kDirs>> meanF(fn.mean.data());
  Eigen::MatrixXd Wsub(rows.size(), kMax);
  for (size_t i = 0; i < rows.size(); ++i) Wsub.row(i) = (D.row(rows[i]).cast<double>() - meanF.cast<double>()) * E.transpose();
  int rank = kMax;
  std::vector<double> errs;
  Eigen::MatrixXd rec = meanF.cast<double>().replicate(Eigen::Index(rows.size()), 1);  // rank-k reconstruction
  for (int k = 0; k <= kMax; ++k) {
    if (k) rec += Wsub.col(k - 1) * E.row(k - 1);
    errs.clear();
    for (size_t i = 0; i < rows.size(); ++i)
      for (int j = 0; j < kDirs; ++j)
        if (hit[size_t(rows[i]) * kDirs + j]) errs.push_back(std::abs(rec(Eigen::Index(i), j) - D(rows[i], j)));
    if (errs.empty()) {
      rank = k;
      break;
    }
    std::nth_element(errs.begin(), errs.begin() + size_t(0.95 * double(errs.size() - 1)), errs.end());
    if (errs[size_t(0.95 * double(errs.size() - 1))] <= opt.tolerance) {
      rank = k;
      break;
    }
  }
  fn.rank = rank;
  fn.basis.resize(size_t(rank) * kDirs);
  for (int k = 0; k < rank; ++k)
    for (int j = 0; j < kDirs; ++j) fn.basis[size_t(k) * kDirs + j] = half(E(k, j));
  fn.weights.resize(size_t(n) * rank);
  for (int r = 0; r < n; ++r)
    for (int k = 0; k < rank; ++k) {
      double w = 0;
      for (int j = 0; j < kDirs; ++j) w += (double(D(r, j)) - fn.mean[j]) * fn.basis[size_t(k) * kDirs + j];
      fn.weights[size_t(r) * rank + k] = half(w);
    }
  // The stored function's error at every hit sample.
  errs.clear();
  double sq = 0;
  for (int r = 0; r < n; ++r)
    for (int j = 0; j < kDirs; ++j)
      if (hit[size_t(r) * kDirs + j]) {
        const double e = std::abs(fn.value(r, j) - D(r, j));
        errs.push_back(e);
        sq += e * e;
      }
  if (!errs.empty()) {
    fn.rmsError = std::sqrt(sq / double(errs.size()));
    std::nth_element(errs.begin(), errs.begin() + size_t(0.95 * double(errs.size() - 1)), errs.end());
    fn.p95Error = errs[size_t(0.95 * double(errs.size() - 1))];
  }
  fn.bakeSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return fn;
}

bool lookup(const PackReader& pack, const CellFunction& fn, const uint16_t* pyramid, double u, double v,
            const Eigen::Vector3d& dir, double& t, LookupStats* stats, bool predictOnly) {
  LookupStats local;
  LookupStats& st = stats ? *stats : local;
  ++st.lookups;
  const CellRecord& c = pack.cells()[fn.cell];
  const Eigen::Vector3d o(u, v, c.box[5]);
  const double tExit = exitDistance(c, o, dir);
  auto fallback = [&] {
    ++st.fallbacks;
    return exact::traceCell(pack, c, pyramid, o, dir, 0, tExit, t);
  };
  // Bilinear weights over the texel centres and over the direction grid.
  const double fx = std::clamp((u - c.box[0]) / (c.box[1] - c.box[0]) * fn.tileW - 0.5, 0.0, double(fn.tileW - 1));
  const double fy = std::clamp((v - c.box[2]) / (c.box[3] - c.box[2]) * fn.tileH - 0.5, 0.0, double(fn.tileH - 1));
  const int x0 = std::min(int(fx), std::max(fn.tileW - 2, 0)), y0 = std::min(int(fy), std::max(fn.tileH - 2, 0));
  const int x1 = std::min(x0 + 1, fn.tileW - 1), y1 = std::min(y0 + 1, fn.tileH - 1);
  const double ax = fx - x0, ay = fy - y0;
  const double theta = std::acos(std::clamp(-dir.z(), -1.0, 1.0));
  double phi = std::atan2(dir.y(), dir.x());
  if (phi < 0) phi += 2 * M_PI;
  const double ft = std::clamp(theta / thetaOf(1), 0.0, double(kThetas - 1));
  const int t0 = std::min(int(ft), kThetas - 2);
  const double at = ft - t0;
  const double fp = phi / phiOf(1);
  const int p0 = int(std::floor(fp)) % kPhis, p1 = (p0 + 1) % kPhis;
  const double ap = fp - std::floor(fp);
  const int texels[4] = {y0 * fn.tileW + x0, y0 * fn.tileW + x1, y1 * fn.tileW + x0, y1 * fn.tileW + x1};
  const double wt[4] = {(1 - ax) * (1 - ay), ax * (1 - ay), (1 - ax) * ay, ax * ay};
  const int dirs[4] = {t0 * kPhis + p0, t0 * kPhis + p1, (t0 + 1) * kPhis + p0, (t0 + 1) * kPhis + p1};
  const double wd[4] = {(1 - at) * (1 - ap), (1 - at) * ap, at * (1 - ap), at * ap};
  int hits = 0;
  double d = 0;
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b) {
      hits += fn.hit(texels[a], dirs[b]);
      d += wt[a] * wd[b] * fn.value(texels[a], dirs[b]);
    }
  if (hits == 0) {
    ++st.missedFast;
    return false;
  }
  if (hits < 16) {
    if (predictOnly) return false;
    return fallback();
  }
  t = d * fn.texel;
  if (predictOnly) return true;
  // Verify: a crossing from above to below within 1.5 texels of the prediction, then false
  // position; else the exact traversal.
  auto gap = [&](double s, bool& cov) {
    const Eigen::Vector3d p = o + dir * s;
    const double h = exact::surfaceHeight(pack, c, p.x(), p.y());
    cov = !std::isnan(h);
    return cov ? p.z() - h : 0.0;
  };
  double lo = std::max(0.0, t - 1.5 * fn.texel), hi = std::min(tExit, t + 1.5 * fn.texel);
  bool cl, ch;
  double gl = gap(lo, cl), gh = gap(hi, ch);
  if (!(cl && ch && gl > 0 && gh <= 0)) return fallback();
  for (int k = 0; k < 3; ++k) {
    const double m = lo + (hi - lo) * gl / (gl - gh);
    bool cm;
    const double gm = gap(m, cm);
    if (!cm) return fallback();
    if (gm > 0) lo = m, gl = gm;
    else hi = m, gh = gm;
  }
  t = gl > 0 && gh <= 0 ? lo + (hi - lo) * gl / (gl - gh) : hi;
  ++st.predicted;
  return true;
}

}  // namespace sa::vdm

// ---- The VDMF section ----------------------------------------------------------------------

namespace sa::vdm {
namespace {

uint16_t halfBits(float x) {
  const Eigen::half h(x);
  uint16_t b;
  std::memcpy(&b, &h, 2);
  return b;
}

float halfValue(uint16_t b) {
  Eigen::half h;
  std::memcpy(static_cast<void*>(&h), &b, 2);  // Eigen::half holds the 16 bits and nothing else
  return float(h);
}

// Upper bound of a cell's block in bytes (the rank at its maximum).
uint64_t blockBound(const CellRecord& c) {
  const uint64_t n = uint64_t(c.tileW) * c.tileH;
  return 4 * (kBlockHeaderWords + kDirs / 2 + uint64_t(kMaxRank) * kDirs / 2 + (n * kMaxRank + 1) / 2 + n * (kDirs / 32));
}

bool meetsClip(const PackReader& pack, const CellRecord& c, const Selection& sel) {
  if (!sel.clip) return true;
  const Eigen::Vector3d origin(pack.meta().origin);
  Eigen::Vector3d lo, hi;
  cellBounds(c, 0, lo, hi);
  return ((lo + origin).array() <= sel.hi.array()).all() && ((hi + origin).array() >= sel.lo.array()).all();
}

void appendBlock(const CellFunction& fn, std::vector<uint32_t>& words) {
  const size_t base = words.size();
  const uint64_t n = uint64_t(fn.tileW) * fn.tileH;
  const uint32_t meanOff = kBlockHeaderWords, basisOff = meanOff + kDirs / 2;
  const uint32_t weightOff = basisOff + uint32_t(fn.rank) * kDirs / 2;
  const uint32_t hitOff = weightOff + uint32_t((n * fn.rank + 1) / 2);
  float texel = float(fn.texel);
  uint32_t texelBits;
  std::memcpy(&texelBits, &texel, 4);
  const uint32_t head[kBlockHeaderWords] = {uint32_t(fn.rank), uint32_t(fn.tileW) | (uint32_t(fn.tileH) << 16), meanOff, basisOff,
                                            weightOff, hitOff, texelBits, 0};
  words.insert(words.end(), head, head + kBlockHeaderWords);
  auto pushHalves = [&](const std::vector<float>& v) {
    for (size_t i = 0; i < v.size(); i += 2)
      words.push_back(uint32_t(halfBits(v[i])) | (i + 1 < v.size() ? uint32_t(halfBits(v[i + 1])) << 16 : 0u));
  };
  pushHalves(fn.mean);
  pushHalves(fn.basis);
  pushHalves(fn.weights);
  words.insert(words.end(), fn.hitBits.begin(), fn.hitBits.end());
  (void)base;
}

}  // namespace

ExtraSection bakeSection(const PackReader& pack, const Selection& sel, const BakeOptions& opt, BakeReport& report,
                         const std::function<void(uint64_t, uint64_t)>& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  auto cells = pack.cells();
  const uint64_t fixed = sizeof(SectionHeader) + 4 * uint64_t(cells.size());
  std::vector<uint32_t> chosen;
  uint64_t bound = fixed;
  for (uint32_t i = 0; i < cells.size(); ++i) {
    if (!meetsClip(pack, cells[i], sel)) continue;
    ++report.candidates;
    const uint64_t b = blockBound(cells[i]);
    if (sel.budget && bound + b > sel.budget) {
      ++report.overBudget;
      continue;
    }
    bound += b;
    chosen.push_back(i);
  }
  std::vector<CellFunction> fns(chosen.size());
  std::atomic<uint64_t> done{0};
  std::mutex progressMutex;
  tbb::parallel_for(size_t(0), chosen.size(), [&](size_t k) {
    std::vector<uint16_t> pyr;
    exact::buildCellPyramid(pack, cells[chosen[k]], pyr);
    fns[k] = bakeCell(pack, chosen[k], pyr.data(), opt);
    const uint64_t d = ++done;
    if (progress) {
      std::lock_guard<std::mutex> lock(progressMutex);
      progress(d, chosen.size());
    }
  });
  SectionHeader h{};
  h.version = kSectionVersion;
  h.cellCount = uint32_t(cells.size());
  h.bakedCells = uint32_t(chosen.size());
  h.thetas = kThetas;
  h.phis = kPhis;
  h.maxThetaDeg = float(kMaxThetaDeg);
  h.tolerance = opt.tolerance;
  h.budget = sel.budget;
  std::vector<uint32_t> entries(cells.size(), kNoEntry), words;
  double rankSum = 0;
  for (size_t k = 0; k < chosen.size(); ++k) {
    entries[chosen[k]] = uint32_t(words.size());
    appendBlock(fns[k], words);
    report.texels += uint64_t(fns[k].tileW) * fns[k].tileH;
    rankSum += fns[k].rank;
  }
  h.wordCount = words.size();
  h.bakeSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ExtraSection s;
  std::memcpy(s.id, kSectionId, 4);
  s.bytes.resize(sizeof(h) + entries.size() * 4 + words.size() * 4);
  std::memcpy(s.bytes.data(), &h, sizeof(h));
  std::memcpy(s.bytes.data() + sizeof(h), entries.data(), entries.size() * 4);
  if (!words.empty()) std::memcpy(s.bytes.data() + sizeof(h) + entries.size() * 4, words.data(), words.size() * 4);
  report.baked = uint32_t(chosen.size());
  report.bytes = s.bytes.size();
  report.seconds = h.bakeSeconds;
  report.meanRank = chosen.empty() ? 0 : rankSum / double(chosen.size());
  return s;
}

Result<SectionView> readSection(const PackReader& pack) {
  const std::span<const uint8_t> b = pack.section(kSectionId);
  SectionView v;
  if (b.empty()) return v;
  const std::string where = pack.path() + ": section VDMF (the vdm mode's functions): ";
  if (b.size() < sizeof(SectionHeader)) return Status::badInput(where + "too short");
  std::memcpy(&v.header, b.data(), sizeof(SectionHeader));
  const SectionHeader& h = v.header;
  if (h.version != kSectionVersion)
    return Status::badInput(where + "version " + std::to_string(h.version) + ", this program reads version " +
                            std::to_string(kSectionVersion) + "; bake it again: scanatlas bake PACK --mode vdm");
  if (h.cellCount != pack.cells().size()) return Status::badInput(where + "made for another cell table (bake it again)");
  if (h.thetas != kThetas || h.phis != kPhis) return Status::badInput(where + "a direction grid this program does not read");
  if (h.wordCount > b.size() / 4 || sizeof(SectionHeader) + 4 * (uint64_t(h.cellCount) + h.wordCount) != b.size())
    return Status::badInput(where + "its size does not match its header");
  v.entries = reinterpret_cast<const uint32_t*>(b.data() + sizeof(SectionHeader));
  v.words = v.entries + h.cellCount;
  for (uint32_t i = 0; i < h.cellCount; ++i) {
    const uint32_t e = v.entries[i];
    if (e == kNoEntry) continue;
    const CellRecord& c = pack.cells()[i];
    if (uint64_t(e) + kBlockHeaderWords > h.wordCount) return Status::badInput(where + "cell " + std::to_string(i) + " lies outside");
    const uint32_t* blk = v.words + e;
    const uint64_t n = uint64_t(c.tileW) * c.tileH, rank = blk[0];
    if (rank > uint64_t(kMaxRank) || (blk[1] & 0xffff) != c.tileW || (blk[1] >> 16) != c.tileH ||
        blk[2] != kBlockHeaderWords || blk[3] != blk[2] + kDirs / 2 || blk[4] != blk[3] + rank * kDirs / 2 ||
        blk[5] != blk[4] + (n * rank + 1) / 2 || uint64_t(e) + blk[5] + n * (kDirs / 32) > h.wordCount)
      return Status::badInput(where + "cell " + std::to_string(i) + "'s block is inconsistent (bake it again)");
  }
  v.present = true;
  v.bytes = b.size();
  return v;
}

CellFunction cellFromSection(const SectionView& v, uint32_t cell) {
  CellFunction fn;
  fn.cell = cell;
  const uint32_t* blk = v.words + v.entries[cell];
  fn.rank = int(blk[0]);
  fn.tileW = int(blk[1] & 0xffff);
  fn.tileH = int(blk[1] >> 16);
  float texel;
  std::memcpy(&texel, &blk[6], 4);
  fn.texel = texel;
  const uint64_t n = uint64_t(fn.tileW) * fn.tileH;
  auto halves = [&](uint32_t off, uint64_t count, std::vector<float>& out) {
    out.resize(count);
    for (uint64_t i = 0; i < count; ++i) out[i] = halfValue(uint16_t(blk[off + i / 2] >> (16 * (i & 1))));
  };
  halves(blk[2], kDirs, fn.mean);
  halves(blk[3], uint64_t(fn.rank) * kDirs, fn.basis);
  halves(blk[4], n * fn.rank, fn.weights);
  fn.hitBits.assign(blk + blk[5], blk + blk[5] + n * (kDirs / 32));
  return fn;
}

}  // namespace sa::vdm
