// Grooves over a whole scan: cubic regions (each with a margin, its own PCA frame and noise),
// lines clipped to their region's core, then joined across regions and across crossings in
// world coordinates, parallel duplicates dropped, simplified (Douglas-Peucker).
#include <algorithm>
#include <array>
#include <atomic>
#include <functional>
#include <unordered_map>
#include <cmath>
#include <map>
#include <mutex>

#include <Eigen/Eigenvalues>
#include <tbb/parallel_for.h>

#include "grooves/grooves.h"
#include "grooves/plane.h"
#include "grooves/raster.h"
#include "preprocess/normals.h"

namespace sa {
namespace {

using Key = std::array<int, 3>;

// Integer ids at points, looked up by cube (the 27 cubes around a query).
class SpatialHash {
 public:
  explicit SpatialHash(double cell) : cell_(cell) {}
  void add(const Eigen::Vector3d& p, int id) { map_[key(p)].push_back(id); }
  template <class F>
  void near(const Eigen::Vector3d& p, F&& f) const {
    const Key k = key(p);
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          auto it = map_.find(Key{k[0] + dx, k[1] + dy, k[2] + dz});
          if (it != map_.end())
            for (int id : it->second) f(id);
        }
  }

 private:
  struct KeyHash {
    size_t operator()(const Key& k) const { return size_t(k[0]) * 73856093u ^ size_t(k[1]) * 19349663u ^ size_t(k[2]) * 83492791u; }
  };
  Key key(const Eigen::Vector3d& p) const {
    return {int(std::floor(p.x() / cell_)), int(std::floor(p.y() / cell_)), int(std::floor(p.z() / cell_))};
  }
  double cell_;
  std::unordered_map<Key, std::vector<int>, KeyHash> map_;
};

struct Fragment {
  std::vector<Eigen::Vector3d> line;
  double width = 0, depth = 0, confidence = 0;
  std::string shape;
  std::vector<std::pair<float, float>> profile;
};

double polyLength(const std::vector<Eigen::Vector3d>& l) {
  double s = 0;
  for (size_t i = 0; i + 1 < l.size(); ++i) s += (l[i + 1] - l[i]).norm();
  return s;
}

// A region's points in its PCA frame; false when they are not one height field over it (more
// than 5 % of 2-spacing cells hold points more than 4 spacings apart in height).
// The frame's normal is turned toward `outside(mean)`.
template <class Outside>
bool planarFrame(const std::vector<Eigen::Vector3d>& world, double s, Outside&& outside, Eigen::Matrix3d& frame,
                 Eigen::Vector3d& mean, std::vector<Eigen::Vector3d>& uvh) {
  mean.setZero();
  for (const Eigen::Vector3d& p : world) mean += p;
  mean /= double(world.size());
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& p : world) C += (p - mean) * (p - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);
  frame.col(0) = es.eigenvectors().col(2);
  frame.col(1) = es.eigenvectors().col(1);
  frame.col(2) = frame.col(0).cross(frame.col(1));
  if (frame.col(2).dot(outside(mean)) < 0) {
    frame.col(1) = -frame.col(1);
    frame.col(2) = -frame.col(2);
  }
  uvh.resize(world.size());
  std::map<std::pair<int, int>, std::pair<double, double>> range;
  for (size_t i = 0; i < world.size(); ++i) {
    uvh[i] = frame.transpose() * (world[i] - mean);
    auto key = std::make_pair(int(std::floor(uvh[i].x() / (2 * s))), int(std::floor(uvh[i].y() / (2 * s))));
    auto [it, fresh] = range.try_emplace(key, uvh[i].z(), uvh[i].z());
    if (!fresh) it->second = {std::min(it->second.first, uvh[i].z()), std::max(it->second.second, uvh[i].z())};
  }
  size_t layered = 0;
  for (const auto& [k, r] : range) layered += r.second - r.first > 4 * s;
  return layered <= range.size() / 20;
}

// Pieces of a region's lines inside its core box [lo, lo + side).
void clipToCore(const grooves::PlaneLine& pl, const Eigen::Matrix3d& frame, const Eigen::Vector3d& mean,
                const Eigen::Vector3d& lo, double side, std::vector<Fragment>& out) {
  Fragment cur;
  auto flush = [&] {
    if (cur.line.size() >= 2) out.push_back(cur);
    cur.line.clear();
  };
  cur.width = pl.width;
  cur.depth = pl.depth;
  cur.confidence = pl.confidence;
  cur.shape = pl.shape;
  cur.profile = pl.profile;
  for (const Eigen::Vector3d& q : pl.uvh) {
    const Eigen::Vector3d w = mean + frame * q;
    const Eigen::Vector3d d = w - lo;
    if ((d.array() >= 0).all() && (d.array() < side).all()) {
      cur.line.push_back(w);
    } else {
      flush();
    }
  }
  flush();
}

// The direction a fragment leaves through its end (0: front, 1: back), over ~2 spacings.
Eigen::Vector3d endTangent(const std::vector<Eigen::Vector3d>& l, int end, double s) {
  const Eigen::Vector3d e = end ? l.back() : l.front();
  Eigen::Vector3d q = e;
  for (size_t k = 1; k < l.size(); ++k) {
    q = end ? l[l.size() - 1 - k] : l[k];
    if ((q - e).norm() >= 2 * s) break;
  }
  const Eigen::Vector3d t = e - q;
  return t.norm() > 0 ? Eigen::Vector3d(t.normalized()) : Eigen::Vector3d::Zero();
}

// Joins fragment ends that continue each other: across region borders (a spacing or less apart)
// and across a crossing groove or a short break (up to 3 spacings + 1.5 widths, nearly straight).
std::vector<std::vector<std::pair<int, bool>>> joinChains(const std::vector<Fragment>& fr, double s) {
  struct Cand {
    double gap;
    int a, ea, b, eb;
  };
  // Ends hashed in cubes as large as the longest allowed gap.
  double maxW = 0;
  for (const Fragment& f : fr) maxW = std::max(maxW, f.width);
  const double cell = 3 * s + 1.5 * maxW;
  SpatialHash ends(cell);
  auto endPoint = [&](int f, int e) -> const Eigen::Vector3d& { return e ? fr[f].line.back() : fr[f].line.front(); };
  for (int f = 0; f < int(fr.size()); ++f)
    for (int e = 0; e < 2; ++e) ends.add(endPoint(f, e), 2 * f + e);
  std::vector<Cand> cands;
  for (int a = 0; a < int(fr.size()); ++a)
    for (int ea = 0; ea < 2; ++ea)
      ends.near(endPoint(a, ea), [&](int code) {
        const int b = code / 2, eb = code % 2;
        if (b <= a) return;
        const Eigen::Vector3d& pa = endPoint(a, ea);
        const Eigen::Vector3d& pb = endPoint(b, eb);
        const double gap = (pb - pa).norm();
        if (gap > 3 * s + 1.5 * std::max(fr[a].width, fr[b].width)) return;
        const Eigen::Vector3d ta = endTangent(fr[a].line, ea, s), tb = endTangent(fr[b].line, eb, s);
        if (ta.dot(tb) > -0.82) return;  // more than ~35 degrees from opposite
        if (gap > s) {
          const Eigen::Vector3d j = (pb - pa) / gap;
          if (ta.dot(j) < 0.87 || tb.dot(-j) < 0.87) return;
        }
        cands.push_back({gap, a, ea, b, eb});
      });
  std::sort(cands.begin(), cands.end(), [](const Cand& x, const Cand& y) { return x.gap < y.gap; });
  std::vector<std::array<int, 2>> link(fr.size(), {-1, -1});  // per end: the other end, encoded 2 f + e
  std::vector<int> chainOf(fr.size());
  for (size_t i = 0; i < fr.size(); ++i) chainOf[i] = int(i);
  std::function<int(int)> root = [&](int i) { return chainOf[i] == i ? i : chainOf[i] = root(chainOf[i]); };
  for (const Cand& c : cands) {
    if (link[c.a][c.ea] >= 0 || link[c.b][c.eb] >= 0 || root(c.a) == root(c.b)) continue;
    link[c.a][c.ea] = 2 * c.b + c.eb;
    link[c.b][c.eb] = 2 * c.a + c.ea;
    chainOf[root(c.a)] = root(c.b);
  }
  std::vector<std::vector<std::pair<int, bool>>> chains;  // (fragment, reversed)
  std::vector<uint8_t> done(fr.size(), 0);
  for (int f = 0; f < int(fr.size()); ++f) {
    if (done[f] || (link[f][0] >= 0 && link[f][1] >= 0)) continue;
    // f has a free end: walk from it.
    std::vector<std::pair<int, bool>> chain;
    int cur = f, enter = link[f][0] < 0 ? 0 : 1;
    while (cur >= 0 && !done[cur]) {
      done[cur] = 1;
      chain.push_back({cur, enter == 1});
      const int next = link[cur][1 - enter];
      if (next < 0) break;
      cur = next / 2;
      enter = next % 2;
    }
    chains.push_back(std::move(chain));
  }
  return chains;
}

void simplify(const std::vector<Eigen::Vector3d>& in, double tol, std::vector<Eigen::Vector3d>& out) {
  std::vector<uint8_t> keep(in.size(), 0);
  keep.front() = keep.back() = 1;
  std::vector<std::pair<size_t, size_t>> stack{{0, in.size() - 1}};
  while (!stack.empty()) {
    auto [a, b] = stack.back();
    stack.pop_back();
    double worst = -1;
    size_t wi = a;
    const Eigen::Vector3d ab = in[b] - in[a];
    for (size_t i = a + 1; i < b; ++i) {
      const double t = ab.squaredNorm() > 0 ? std::clamp((in[i] - in[a]).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 0;
      const double d = (in[a] + t * ab - in[i]).norm();
      if (d > worst) worst = d, wi = i;
    }
    if (worst > tol) {
      keep[wi] = 1;
      stack.push_back({a, wi});
      stack.push_back({wi, b});
    }
  }
  out.clear();
  for (size_t i = 0; i < in.size(); ++i)
    if (keep[i]) out.push_back(in[i]);
}

Groove mergeChain(const std::vector<Fragment>& fr, const std::vector<std::pair<int, bool>>& chain, double s) {
  Groove g;
  std::vector<Eigen::Vector3d> pts;
  double wsum = 0, longest = -1;
  std::map<std::string, double> shapes;
  for (auto [f, rev] : chain) {
    const Fragment& x = fr[f];
    if (rev) pts.insert(pts.end(), x.line.rbegin(), x.line.rend());
    else pts.insert(pts.end(), x.line.begin(), x.line.end());
    const double len = std::max(polyLength(x.line), 1e-9);
    g.width += len * x.width;
    g.depth += len * x.depth;
    g.confidence += len * x.confidence;
    wsum += len;
    shapes[x.shape] += len;
    if (len > longest) longest = len, g.profile = x.profile;
  }
  g.width /= wsum;
  g.depth /= wsum;
  g.confidence /= wsum;
  g.shape = std::max_element(shapes.begin(), shapes.end(), [](auto& a, auto& b) { return a.second < b.second; })->first;
  // Douglas-Peucker to a quarter of a pack texel (half a spacing).
  simplify(pts, 0.125 * s, g.line);
  g.length = polyLength(pts);
  return g;
}

// Points every half spacing along a line.
std::vector<Eigen::Vector3d> resample(const std::vector<Eigen::Vector3d>& l, double step) {
  std::vector<Eigen::Vector3d> out;
  for (size_t k = 0; k + 1 < l.size(); ++k) {
    const int n = std::max(1, int(std::ceil((l[k + 1] - l[k]).norm() / step)));
    for (int t = 0; t < n; ++t) out.push_back(l[k] + (l[k + 1] - l[k]) * (double(t) / n));
  }
  if (!l.empty()) out.push_back(l.back());
  return out;
}

// Drops a groove when 70 % of it lies within half a width (at least a spacing) of a longer one
// already kept: a wide valley's second line, a line found twice.
void dropDuplicates(std::vector<Groove>& gs, double s) {
  std::sort(gs.begin(), gs.end(), [](const Groove& a, const Groove& b) { return a.length > b.length; });
  double maxW = s;
  for (const Groove& g : gs) maxW = std::max(maxW, g.width);
  SpatialHash hash(maxW);
  std::vector<Eigen::Vector3d> samples;
  std::vector<double> reach;
  std::vector<Groove> kept;
  for (Groove& g : gs) {
    const std::vector<Eigen::Vector3d> mine = resample(g.line, s / 2);
    size_t near = 0;
    for (const Eigen::Vector3d& p : mine) {
      bool hit = false;
      hash.near(p, [&](int id) { hit = hit || (samples[id] - p).norm() <= reach[id]; });
      near += hit;
    }
    if (near * 10 >= mine.size() * 7) continue;
    for (const Eigen::Vector3d& p : mine) {
      hash.add(p, int(samples.size()));
      samples.push_back(p);
      reach.push_back(std::max(g.width / 2, s));
    }
    kept.push_back(std::move(g));
  }
  gs = std::move(kept);
}

// A cube [lo, lo + side) whose lines are kept; its points are gathered with a margin around it.
struct Region {
  Eigen::Vector3d lo;
  double side = 0;
};

// The points in cubes of `side` (indices), for gathering a box's points with a margin.
class SceneIndex {
 public:
  SceneIndex(const double* pos, size_t n, double side, double margin) : pos_(pos), side_(side), margin_(margin) {
    lo_ = Eigen::Vector3d(pos[0], pos[1], pos[2]);
    for (size_t i = 0; i < n; ++i) lo_ = lo_.cwiseMin(Eigen::Vector3d(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]));
    for (size_t i = 0; i < n; ++i) {
      Key k;
      for (int a = 0; a < 3; ++a) k[a] = int(std::floor((pos[3 * i + a] - lo_[a]) / side));
      blocks_[k].push_back(uint32_t(i));
    }
  }
  // The cubes holding at least 64 points.
  std::vector<Region> regions() const {
    std::vector<Region> out;
    for (const auto& [k, v] : blocks_)
      if (v.size() >= 64) out.push_back({lo_ + Eigen::Vector3d(k[0], k[1], k[2]) * side_, side_});
    return out;
  }
  // The points of the box [lo, lo + size) grown by the margin; returns how many lie in the box.
  size_t gather(const Eigen::Vector3d& lo, const Eigen::Vector3d& size, std::vector<Eigen::Vector3d>& world) const {
    Key k0, k1;
    for (int a = 0; a < 3; ++a) {
      k0[a] = int(std::floor((lo[a] - margin_ - lo_[a]) / side_));
      k1[a] = int(std::floor((lo[a] + size[a] + margin_ - lo_[a]) / side_));
    }
    size_t inside = 0;
    for (int z = k0[2]; z <= k1[2]; ++z)
      for (int y = k0[1]; y <= k1[1]; ++y)
        for (int x = k0[0]; x <= k1[0]; ++x) {
          auto it = blocks_.find(Key{x, y, z});
          if (it == blocks_.end()) continue;
          for (uint32_t i : it->second) {
            const Eigen::Vector3d p(pos_[3 * i], pos_[3 * i + 1], pos_[3 * i + 2]);
            const Eigen::Vector3d d = p - lo;
            if (!(d.array() >= -margin_).all() || !(d.array() < size.array() + margin_).all()) continue;
            world.push_back(p);
            inside += (d.array() >= 0).all() && (d.array() < size.array()).all();
          }
        }
    return inside;
  }
  size_t gather(const Eigen::Vector3d& lo, double side, std::vector<Eigen::Vector3d>& world) const {
    return gather(lo, Eigen::Vector3d::Constant(side), world);
  }

 private:
  const double* pos_;
  double side_, margin_;
  Eigen::Vector3d lo_;
  std::map<Key, std::vector<uint32_t>> blocks_;
};

struct SceneSide {
  bool planar = false;
  Eigen::Vector3d dir = Eigen::Vector3d::Zero(), centroid = Eigen::Vector3d::Zero();
};

// Which side grooves open to: the given one; for a nearly planar scene (smallest extent under
// 10 % of the middle one) the side of its normal that the regions' residuals lean below;
// otherwise away from the centroid.
template <class Gather>
SceneSide decideSide(const double* pos, size_t n, const GrooveOptions& opt, const std::vector<Region>& regions,
                     Gather&& gather, double s) {
  SceneSide side;
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < n; ++i) side.centroid += Eigen::Vector3d(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]);
  side.centroid /= double(n);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d d = Eigen::Vector3d(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]) - side.centroid;
    C += d * d.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);
  side.planar = es.eigenvalues()(0) < 0.01 * es.eigenvalues()(1);
  side.dir = es.eigenvectors().col(0);
  if (opt.outside.norm() > 0) {
    side.planar = true;
    side.dir = opt.outside.normalized();
    return side;
  }
  if (!side.planar) return side;
  std::mutex mu;
  double evidence = 0;
  tbb::parallel_for(size_t(0), regions.size(), [&](size_t r) {
    std::vector<Eigen::Vector3d> world, uvh;
    gather(regions[r], world);
    Eigen::Matrix3d frame;
    Eigen::Vector3d mean;
    if (!planarFrame(world, s, [&](const Eigen::Vector3d&) { return side.dir; }, frame, mean, uvh)) return;
    const double e = grooves::sideEvidence(uvh, s, opt);
    std::lock_guard<std::mutex> lock(mu);
    evidence += e;
  });
  if (evidence < 0) side.dir = -side.dir;
  return side;
}

}  // namespace

GrooveSet detectGrooves(const double* pos, size_t n, const GrooveOptions& opt) {
  GrooveSet set;
  if (n < 16) return set;
  set.spacing = opt.spacing > 0 ? opt.spacing : estimateSpacing(pos, n).area;
  const double s = set.spacing, side = opt.region * s;
  const SceneIndex index(pos, n, side, 2 * opt.maxWidth * s);
  std::vector<Region> regions = index.regions();
  auto gather = [&](const Region& r, std::vector<Eigen::Vector3d>& world) { return index.gather(r.lo, r.side, world); };
  const SceneSide sceneSide = decideSide(pos, n, opt, regions, gather, s);
  auto outside = [&](const Eigen::Vector3d& m) { return sceneSide.planar ? sceneSide.dir : Eigen::Vector3d(m - sceneSide.centroid); };
  std::vector<Fragment> all;
  std::vector<float> ns;
  std::atomic<uint64_t> done{0};
  std::atomic<uint32_t> skipped{0};
  std::mutex mu;
  // A region that is not one height field is split in eight, down to a quarter of the side.
  const double minSide = side / 4 - 1e-9;
  while (!regions.empty()) {
    std::vector<Region> next;
    set.regions += uint32_t(regions.size());
    tbb::parallel_for(size_t(0), regions.size(), [&](size_t ri) {
      const Region& r = regions[ri];
      std::vector<Eigen::Vector3d> world, uvh;
      const size_t inside = gather(r, world);
      Eigen::Matrix3d frame;
      Eigen::Vector3d mean;
      std::vector<Fragment> mine;
      double noise = -1;
      bool split = false;
      if (inside < 32) {
      } else if (planarFrame(world, s, outside, frame, mean, uvh)) {
        const grooves::PlaneResult pr = grooves::detectInPlane(uvh, s, opt);
        noise = pr.noise;
        for (const grooves::PlaneLine& pl : pr.lines) clipToCore(pl, frame, mean, r.lo, r.side, mine);
      } else if (r.side / 2 >= minSide) {
        split = true;
      } else {
        ++skipped;
      }
      std::lock_guard<std::mutex> lock(mu);
      all.insert(all.end(), std::make_move_iterator(mine.begin()), std::make_move_iterator(mine.end()));
      if (noise >= 0) ns.push_back(float(noise));
      if (split)
        for (int c = 0; c < 8; ++c)
          next.push_back({r.lo + Eigen::Vector3d(c & 1, (c >> 1) & 1, (c >> 2) & 1) * (r.side / 2), r.side / 2});
      const uint64_t d = ++done;
      if (opt.progress) opt.progress(d, d + (regions.size() - std::min<size_t>(regions.size(), d)) + next.size());
    });
    regions = std::move(next);
  }
  if (opt.progress) opt.progress(done, done);
  set.noise = grooves::median(ns);
  set.skippedRegions = skipped;
  for (const auto& chain : joinChains(all, s)) {
    Groove g = mergeChain(all, chain, s);
    if (g.length >= opt.minLength * s) set.grooves.push_back(std::move(g));
  }
  dropDuplicates(set.grooves, s);
  return set;
}

namespace {

// A given groove's polyline cut into pieces of at most `len` (sharing their end points).
std::vector<std::vector<Eigen::Vector3d>> piecesOf(const std::vector<Eigen::Vector3d>& line, double step, double len) {
  const std::vector<Eigen::Vector3d> dense = resample(line, step);
  std::vector<std::vector<Eigen::Vector3d>> out(1);
  double run = 0;
  for (size_t k = 0; k < dense.size(); ++k) {
    if (k) run += (dense[k] - dense[k - 1]).norm();
    out.back().push_back(dense[k]);
    if (run >= len && k + 1 < dense.size()) {
      out.push_back({dense[k]});
      run = 0;
    }
  }
  return out;
}

}  // namespace

GrooveSet measureGrooves(const double* pos, size_t n, const GrooveSet& given, const GrooveOptions& opt) {
  GrooveSet set;
  set.grooves = given.grooves;
  set.unmeasured = uint32_t(given.grooves.size());
  if (n < 16) return set;
  set.spacing = opt.spacing > 0 ? opt.spacing : estimateSpacing(pos, n).area;
  const double s = set.spacing;
  const SceneIndex index(pos, n, opt.region * s, 3 * opt.maxWidth * s);
  auto gather = [&](const Region& r, std::vector<Eigen::Vector3d>& world) { return index.gather(r.lo, r.side, world); };
  const SceneSide sceneSide = decideSide(pos, n, opt, index.regions(), gather, s);
  auto outside = [&](const Eigen::Vector3d& m) { return sceneSide.planar ? sceneSide.dir : Eigen::Vector3d(m - sceneSide.centroid); };
  struct Piece {
    size_t groove;
    std::vector<Eigen::Vector3d> line;
    Fragment measured;
    double noise = -1;
  };
  std::vector<Piece> pieces;
  for (size_t gi = 0; gi < given.grooves.size(); ++gi)
    for (auto& l : piecesOf(given.grooves[gi].line, s / 2, opt.region * s)) pieces.push_back({gi, std::move(l), {}, -1});
  tbb::parallel_for(size_t(0), pieces.size(), [&](size_t k) {
    Piece& pc = pieces[k];
    if (pc.line.size() < 2) return;
    Eigen::Vector3d lo = pc.line[0], hi = pc.line[0];
    for (const Eigen::Vector3d& p : pc.line) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
    std::vector<Eigen::Vector3d> world, uvh;
    index.gather(lo, hi - lo, world);
    Eigen::Matrix3d frame;
    Eigen::Vector3d mean;
    if (world.size() < 16 || !planarFrame(world, s, outside, frame, mean, uvh)) return;
    std::vector<Eigen::Vector2d> uv;
    for (const Eigen::Vector3d& p : pc.line) uv.push_back((frame.transpose() * (p - mean)).head<2>());
    grooves::PlaneLine pl;
    double noise = 0;
    if (!grooves::measureInPlane(uvh, uv, s, opt, pl, noise)) return;
    pc.noise = noise;
    for (const Eigen::Vector3d& q : pl.uvh) pc.measured.line.push_back(mean + frame * q);
    pc.measured.width = pl.width;
    pc.measured.depth = pl.depth;
    pc.measured.shape = pl.shape;
    pc.measured.profile = pl.profile;
    pc.measured.confidence = given.grooves[pc.groove].confidence;
  });
  // Per groove: its measured pieces merged (lines joined end to end, values length-weighted).
  std::vector<std::vector<std::pair<int, bool>>> chains(given.grooves.size());
  std::vector<Fragment> frags;
  std::vector<float> ns;
  for (Piece& pc : pieces) {
    if (pc.noise < 0) continue;
    chains[pc.groove].push_back({int(frags.size()), false});
    frags.push_back(std::move(pc.measured));
    ns.push_back(float(pc.noise));
  }
  set.unmeasured = 0;
  for (size_t gi = 0; gi < given.grooves.size(); ++gi) {
    if (chains[gi].empty()) {
      ++set.unmeasured;  // kept as given
      continue;
    }
    set.grooves[gi] = mergeChain(frags, chains[gi], s);
  }
  set.noise = grooves::median(ns);
  return set;
}

}  // namespace sa
