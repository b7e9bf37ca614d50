#include "preprocess/grid_knn.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace sa {
namespace {

constexpr int64_t kMaxDim = int64_t(1) << 20;
constexpr int kMaxRing = 3;  // beyond: every cell, pruned by its distance

uint64_t hashKey(uint64_t k) { return k * 0x9E3779B97F4A7C15ull; }
// A key's first slot in a table of mask + 1 slots (linear probing from there).
uint64_t slotOf(uint64_t key, uint64_t mask) { return (hashKey(key) >> 20) & mask; }

// Morton order: the bits of x, y and z interleaved, so cells close in space are mostly close in
// the sorted order (a point's neighbours then lie in nearby memory, also for callers that
// process points in the grid's order).
uint64_t spread(uint64_t v) {  // 21 bits -> every third bit of 63
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffull;
  v = (v | v << 16) & 0x1f0000ff0000ffull;
  v = (v | v << 8) & 0x100f00f00f00f00full;
  v = (v | v << 4) & 0x10c30c30c30c30c3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}

uint64_t compact(uint64_t v) {  // the inverse of spread
  v &= 0x1249249249249249ull;
  v = (v ^ (v >> 2)) & 0x10c30c30c30c30c3ull;
  v = (v ^ (v >> 4)) & 0x100f00f00f00f00full;
  v = (v ^ (v >> 8)) & 0x1f0000ff0000ffull;
  v = (v ^ (v >> 16)) & 0x1f00000000ffffull;
  v = (v ^ (v >> 32)) & 0x1fffff;
  return v;
}

}  // namespace

namespace {

// A point's cell key and index. Arrays of it are made without zeroing them: their first writes
// are the parallel loops' that fill them, so the pages are first touched (and cleared by the
// kernel) on every core instead of by one memset (those were most of the grid's serial time).
struct Keyed {
  uint64_t first;
  uint32_t second;
};
using KeyedArray = RawVector<Keyed>;

// (key, index) pairs made in index order, sorted by key and then index: a stable radix sort on
// the key over its used bits, 11 at a time, each pass counted and scattered by blocks on every
// core (the comparison sort's first partitions ran on one core).
void sortKeyed(KeyedArray& keyed, size_t n) {
  constexpr size_t kBlock = 1 << 15;
  constexpr int kBits = 11, kDigits = 1 << kBits;
  uint64_t any = 0;
  for (size_t i = 0; i < n; ++i) any |= keyed[i].first;
  const size_t blocks = (n + kBlock - 1) / kBlock;
  KeyedArray tmp(n);
  std::vector<uint32_t> at(blocks * kDigits);
  for (int shift = 0; shift < 64 && (any >> shift); shift += kBits) {
    tbb::parallel_for(size_t(0), blocks, [&](size_t b) {
      uint32_t* h = &at[b * kDigits];
      std::fill(h, h + kDigits, 0u);
      for (size_t i = b * kBlock, e = std::min(n, i + kBlock); i < e; ++i) ++h[(keyed[i].first >> shift) & (kDigits - 1)];
    });
    uint32_t sum = 0;  // where each block's run of each digit starts: digits in order, blocks in order within
    for (size_t d = 0; d < size_t(kDigits); ++d)
      for (size_t b = 0; b < blocks; ++b) {
        const uint32_t c = at[b * kDigits + d];
        at[b * kDigits + d] = sum;
        sum += c;
      }
    tbb::parallel_for(size_t(0), blocks, [&](size_t b) {
      uint32_t* h = &at[b * kDigits];
      for (size_t i = b * kBlock, e = std::min(n, i + kBlock); i < e; ++i) tmp[h[(keyed[i].first >> shift) & (kDigits - 1)]++] = keyed[i];
    });
    keyed.swap(tmp);
  }
}

}  // namespace

void pointBounds(const double* pos, size_t n, double lo[3], double hi[3]) {
  using Box = std::array<double, 6>;  // lo, hi
  const double inf = std::numeric_limits<double>::infinity();
  const Box box = tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, n, 1 << 15), Box{inf, inf, inf, -inf, -inf, -inf},
      [&](const tbb::blocked_range<size_t>& r, Box b) {
        for (size_t i = r.begin(); i != r.end(); ++i)
          for (int a = 0; a < 3; ++a) b[a] = std::min(b[a], pos[3 * i + a]), b[3 + a] = std::max(b[3 + a], pos[3 * i + a]);
        return b;
      },
      [](Box a, const Box& b) {
        for (int k = 0; k < 3; ++k) a[k] = std::min(a[k], b[k]), a[3 + k] = std::max(a[3 + k], b[3 + k]);
        return a;
      });
  for (int a = 0; a < 3; ++a) lo[a] = box[a], hi[a] = box[3 + a];
}

double GridKnn::cellFor(double spacing, int k) { return 1.3 * spacing * std::sqrt(std::max(k, 1) / M_PI); }

GridKnn::GridKnn(const double* pos, size_t n, double cell) : pos_(pos), n_(n), cell_(cell), sortedPos_(nullptr) {
  double hi[3];
  pointBounds(pos, n, lo_, hi);
  double extent = 0;
  for (int a = 0; a < 3; ++a) extent = n ? std::max(extent, hi[a] - lo_[a]) : 0;
  if (!(cell_ > 0) || !std::isfinite(cell_)) cell_ = extent > 0 ? extent / 64 : 1;
  if (extent / cell_ >= double(kMaxDim - 1)) cell_ = extent / double(kMaxDim - 2);
  for (int a = 0; a < 3; ++a) dims_[a] = n ? int64_t(std::floor((hi[a] - lo_[a]) / cell_)) + 1 : 1;
  KeyedArray keyed(n);
  constexpr size_t kGrain = 1 << 14;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, kGrain), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      int64_t c[3];
      coords(i, c);
      keyed[i] = {keyOf(c[0], c[1], c[2]), uint32_t(i)};
    }
  });
  sortKeyed(keyed, n);
  order_.resize(n);
  sorted_.resize(3 * n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, kGrain), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      order_[i] = keyed[i].second;
      for (int a = 0; a < 3; ++a) sorted_[3 * i + a] = pos[3 * size_t(keyed[i].second) + a];
    }
  });
  sortedPos_ = sorted_.data();
  for (size_t i = 0; i < n; ++i) {
    if (i == 0 || keyed[i].first != keyed[i - 1].first) cells_.push_back({keyed[i].first, uint32_t(i), uint32_t(i)});
    cells_.back().end = uint32_t(i + 1);
  }
  size_t size = 16;
  while (size < 2 * cells_.size()) size *= 2;
  mask_ = size - 1;
  table_.assign(size, Slot{0, -1});
  for (size_t c = 0; c < cells_.size(); ++c) {
    uint64_t h = slotOf(cells_[c].key, mask_);
    while (table_[h].cell >= 0) h = (h + 1) & mask_;
    table_[h] = {cells_[c].key, int64_t(c)};
  }
}

// The points' extent, the cells and their Morton order are the same for any numbering of the
// points; within a cell the points stay in the same sequence (by index before, by place now).
GridKnn GridKnn::inOrder(RawVector<double>& src, std::vector<uint32_t>& orig) && {
  GridKnn g = std::move(*this);
  orig = std::move(g.order_);
  src = std::move(g.sorted_);
  g.pos_ = g.sortedPos_ = src.data();
  g.order_.resize(g.n_);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, g.n_, 1 << 16), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) g.order_[i] = uint32_t(i);
  });
  return g;
}

uint64_t GridKnn::keyOf(int64_t x, int64_t y, int64_t z) const {
  return spread(uint64_t(x)) | spread(uint64_t(y)) << 1 | spread(uint64_t(z)) << 2;
}

void GridKnn::coords(size_t i, int64_t c[3]) const {
  for (int a = 0; a < 3; ++a)
    c[a] = std::clamp(int64_t(std::floor((pos_[3 * i + a] - lo_[a]) / cell_)), int64_t(0), dims_[a] - 1);
}

int64_t GridKnn::findCell(uint64_t key) const {
  uint64_t h = slotOf(key, mask_);
  while (table_[h].cell >= 0) {
    if (table_[h].key == key) return table_[h].cell;
    h = (h + 1) & mask_;
  }
  return -1;
}

// A cell's key is the or of its coordinates' spread bits: each z and y is spread once per row, and
// each x once per call where the rows are short (a block's three), not once per cell. The keys
// are looked up in batches: each batch's hash slots are fetched ahead first (the table is larger
// than the caches, and the slots of neighbouring cells lie anywhere in it: the lookups were 3 % of
// a pack's cycles under perf, against 0.2 % of its instructions), then visited in the same order.
template <class F>
void GridKnn::forCells(const int64_t a[3], const int64_t b[3], F visit) const {
  constexpr int64_t kRow = 16;
  constexpr int kBatch = 32;
  uint64_t sx[kRow], keys[kBatch];
  int batched = 0;
  auto flush = [&] {
    for (int q = 0; q < batched; ++q) __builtin_prefetch(&table_[slotOf(keys[q], mask_)]);
    for (int q = 0; q < batched; ++q) {
      const int64_t ci = findCell(keys[q]);
      if (ci >= 0) visit(cells_[size_t(ci)]);
    }
    batched = 0;
  };
  const bool kept = b[0] - a[0] < kRow;
  if (kept)
    for (int64_t x = a[0]; x <= b[0]; ++x) sx[x - a[0]] = spread(uint64_t(x));
  for (int64_t z = a[2]; z <= b[2]; ++z) {
    const uint64_t kz = spread(uint64_t(z)) << 2;
    for (int64_t y = a[1]; y <= b[1]; ++y) {
      const uint64_t kyz = kz | spread(uint64_t(y)) << 1;
      for (int64_t x = a[0]; x <= b[0]; ++x) {
        keys[batched++] = kyz | (kept ? sx[x - a[0]] : spread(uint64_t(x)));
        if (batched == kBatch) flush();
      }
    }
  }
  flush();
}

void GridKnn::gather(const int64_t c[3], int ring, Candidates& out) const {
  out.index.clear();
  out.x.clear(), out.y.clear(), out.z.clear();
  int64_t a[3], b[3];
  for (int k = 0; k < 3; ++k) a[k] = std::max<int64_t>(0, c[k] - ring), b[k] = std::min(dims_[k] - 1, c[k] + ring);
  forCells(a, b, [&](const Cell& cc) {
    out.index.insert(out.index.end(), order_.begin() + cc.begin, order_.begin() + cc.end);
    for (uint32_t o = cc.begin; o < cc.end; ++o) {
      const double* q = &sortedPos_[3 * size_t(o)];
      out.x.push_back(q[0]), out.y.push_back(q[1]), out.z.push_back(q[2]);
    }
  });
}

namespace {
// (distance, index) pairs in ascending order, as std::pair's < orders them for distances that are
// not NaN, without the three-way comparison's extra branches.
bool nearer(const std::pair<double, uint32_t>& a, const std::pair<double, uint32_t>& b) {
  return a.first < b.first || (a.first == b.first && a.second < b.second);
}
}  // namespace

// The m = min(k, candidates) smallest (d2, index) of `from` into best (ascending) when at least m
// lie within b2; false otherwise. The distances come first, in one loop the compiler vectorizes;
// then a histogram of 64 buckets over [0, b2] (or over [0, the farthest] for an unbounded ask)
// finds the bucket of the m-th, and only the candidates up to that bucket are selected and
// sorted. The selection was most of a query; on a surface the count grows with d2, so the
// buckets hold about equally many and a query sorts about k + k / 10 instead of 3k. Exact: the
// bucket of a distance never decreases as the distance grows, so every candidate left out is
// farther than every one kept.
bool GridKnn::select(const double* p, Candidates& from, int k, double b2,
                     std::vector<std::pair<double, uint32_t>>& best) const {
  const size_t nc = from.index.size(), m = std::min(nc, size_t(k));
  best.clear();
  from.d2.resize(nc);
  const double px = p[0], py = p[1], pz = p[2];
  const double *x = from.x.data(), *y = from.y.data(), *z = from.z.data();
  double* d2 = from.d2.data();
  double far = 0;
  for (size_t j = 0; j < nc; ++j) {
    const double dx = x[j] - px, dy = y[j] - py, dz = z[j] - pz;
    d2[j] = dx * dx + dy * dy + dz * dz;
  }
  if (!(b2 < std::numeric_limits<double>::infinity())) {
    for (size_t j = 0; j < nc; ++j) far = std::max(far, d2[j]);
    b2 = far;
  }
  // The candidates within b2, in one branch-free pass (on a surface a tight bound keeps about
  // half of the block); the histogram then reads only those.
  from.near.resize(nc);
  uint32_t* near = from.near.data();
  size_t nn = 0;
  for (size_t j = 0; j < nc; ++j) {
    near[nn] = uint32_t(j);
    nn += d2[j] <= b2;
  }
  if (nn < m) return false;  // fewer than m within b2
  // 64 buckets: about one candidate each on a surface, so that the kept ones reach the insertion
  // sort below nearly in order and its loop mostly exits at once (with 32, two to a bucket in
  // random order, its exits were most of the query's mispredicted branches).
  constexpr int kBuckets = 64;
  const double scale = b2 > 0 ? kBuckets / b2 : 0;
  // Bucket of each (d2 <= b2: one at b2 itself, or a product rounded up to kBuckets, goes in
  // the last, which keeps the answer exact: only the buckets' order matters).
  from.bucket.resize(nn);
  uint16_t* bk = from.bucket.data();
  uint32_t count[kBuckets] = {};
  for (size_t a = 0; a < nn; ++a) {
    const double f = d2[near[a]] * scale;
    const int b = f < kBuckets ? int(f) : kBuckets - 1;  // NaN (0 times an infinite scale): the last
    bk[a] = uint16_t(b);
    ++count[b];
  }
  int last = 0;  // the bucket the m-th lies in
  for (size_t sum = 0; last < kBuckets - 1; ++last)
    if ((sum += count[last]) >= m) break;
  // The candidates up to that bucket, placed by bucket (a counting sort), so that only the last
  // bucket is selected from and the whole is nearly in order. The buckets past it all write to
  // one slot past the kept ones and never advance: no branch on whether a candidate is kept.
  uint32_t end[kBuckets];
  uint32_t kept = 0;
  for (int b = 0; b <= last; ++b) end[b] = kept, kept += count[b];
  for (int b = last + 1; b < kBuckets; ++b) end[b] = kept;
  best.resize(kept + 1);
  for (size_t a = 0; a < nn; ++a) {
    const uint32_t j = near[a], b = bk[a];
    best[end[b]] = {d2[j], from.index[j]};
    end[b] += b <= uint32_t(last);
  }
  const auto first = best.begin() + (end[last] - count[last]);
  best.resize(kept);
  if (m < kept) std::nth_element(first, best.begin() + long(m - 1), best.end(), nearer);
  best.resize(m);
  // Insertion sort: the buckets are in order, each holds a candidate or none on a surface.
  for (size_t a = 1; a < m; ++a) {
    const std::pair<double, uint32_t> e = best[a];
    size_t b = a;
    for (; b > 0 && nearer(e, best[b - 1]); --b) best[b] = best[b - 1];
    best[b] = e;
  }
  return true;
}

// The k smallest (d2, index) of point i over `cand` into scratch (ascending), then, where the
// candidates cannot prove it (the k-th lies beyond the gathered block), wider rings and at last
// every cell, pruned by distance.
void GridKnn::nearest(size_t i, const int64_t c[3], Candidates& cand, int k, std::vector<std::pair<double, uint32_t>>& best,
                      double bound2) const {
  const double* p = pos_ + 3 * i;
  // The k smallest of the candidates within bound2 if there are k of them (every candidate
  // left out is then farther than all kept), else of all.
  const double all = std::numeric_limits<double>::infinity();
  if (!select(p, cand, k, bound2, best)) select(p, cand, k, all, best);
  const size_t want = std::min(n_, size_t(k));
  auto proven = [&](int ring) {
    const double g = reach(p, c, ring);
    return best.size() == want && (std::isinf(g) || best.back().first < g * g);
  };
  if (proven(1)) return;
  Candidates more;
  for (int ring = 2; ring <= kMaxRing; ++ring) {
    gather(c, ring, more);
    select(p, more, k, all, best);
    if (proven(ring)) return;
  }
  // Far from everything (an outlier, a sparse fringe): every cell that can hold a closer point.
  for (const Cell& cc : cells_) {
    const int64_t cx[3] = {int64_t(compact(cc.key)), int64_t(compact(cc.key >> 1)), int64_t(compact(cc.key >> 2))};
    double d2 = 0;
    for (int a = 0; a < 3; ++a) {
      const double b0 = lo_[a] + double(cx[a]) * cell_, b1 = b0 + cell_;
      const double d = p[a] < b0 ? b0 - p[a] : (p[a] > b1 ? p[a] - b1 : 0);
      d2 += d * d;
    }
    if (best.size() == want && d2 > best.back().first) continue;
    for (uint32_t o = cc.begin; o < cc.end; ++o) {
      const uint32_t j = order_[o];
      const double* q = &sortedPos_[3 * size_t(o)];
      const double dx = q[0] - p[0], dy = q[1] - p[1], dz = q[2] - p[2];
      const std::pair<double, uint32_t> e(dx * dx + dy * dy + dz * dz, j);
      if (std::find(best.begin(), best.end(), e) != best.end()) continue;
      if (best.size() < want) {
        best.push_back(e);
      } else if (e < best.back()) {
        best.back() = e;
      } else {
        continue;
      }
      std::sort(best.begin(), best.end());
    }
  }
}

double GridKnn::reach(const double* p, const int64_t c[3], int ring) const {
  double g = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (c[a] - ring > 0) g = std::min(g, p[a] - (lo_[a] + double(c[a] - ring) * cell_));
    if (c[a] + ring < dims_[a] - 1) g = std::min(g, lo_[a] + double(c[a] + ring + 1) * cell_ - p[a]);
  }
  return g;
}

RawVector<float> GridKnn::blockRank(const float* value, size_t t) const {
  RawVector<float> out(n_);  // not zeroed: the cells hold every point, each written once below
  tbb::parallel_for(tbb::blocked_range<size_t>(0, cells_.size(), 64), [&](const tbb::blocked_range<size_t>& r) {
    std::vector<float> v;
    for (size_t ci = r.begin(); ci != r.end(); ++ci) {
      const Cell& cc = cells_[ci];
      int64_t c[3], a[3], b[3];
      coords(order_[cc.begin], c);
      for (int k = 0; k < 3; ++k) a[k] = std::max<int64_t>(0, c[k] - 1), b[k] = std::min(dims_[k] - 1, c[k] + 1);
      v.clear();
      forCells(a, b, [&](const Cell& nb) {
        for (uint32_t o = nb.begin; o < nb.end; ++o) v.push_back(value[order_[o]]);
      });
      float x = -std::numeric_limits<float>::infinity();
      if (v.size() > t) {
        std::nth_element(v.begin(), v.begin() + long(t), v.end());
        x = v[t];
      }
      for (uint32_t o = cc.begin; o < cc.end; ++o) out[order_[o]] = x;
    }
  });
  return out;
}

void GridKnn::forEach(int k, const Visit& fn) const {
  if (n_ == 0 || k <= 0) return;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, cells_.size(), 64), [&](const tbb::blocked_range<size_t>& r) {
    Candidates cand;
    std::vector<std::pair<double, uint32_t>> best;
    std::vector<int> ind(static_cast<size_t>(k));
    std::vector<double> d2(static_cast<size_t>(k));
    for (size_t ci = r.begin(); ci != r.end(); ++ci) {
      const Cell& cc = cells_[ci];
      int64_t c[3];
      coords(order_[cc.begin], c);
      gather(c, 1, cand);
      // Each point's bound: the previous point's k-th distance plus the distance between them
      // (the previous point's k neighbours are all that close).
      double prevR = -1;
      const double* prev = nullptr;
      for (uint32_t o = cc.begin; o < cc.end; ++o) {
        const size_t i = order_[o];
        const double* p = pos_ + 3 * i;
        double bound2 = std::numeric_limits<double>::infinity();
        if (prevR >= 0) {
          const double dx = p[0] - prev[0], dy = p[1] - prev[1], dz = p[2] - prev[2];
          const double r = prevR + std::sqrt(dx * dx + dy * dy + dz * dz);
          bound2 = r * r * (1 + 1e-9);
        }
        nearest(i, c, cand, k, best, bound2);
        if (best.size() == size_t(k)) prevR = std::sqrt(best.back().first), prev = p;
        for (size_t j = 0; j < best.size(); ++j) ind[j] = int(best[j].second), d2[j] = best[j].first;
        fn(i, ind.data(), d2.data(), int(best.size()));
      }
    }
  });
}

void GridKnn::within(const double* q, double radius, std::vector<std::pair<double, uint32_t>>& out, bool ordered) const {
  out.clear();
  if (n_ == 0 || !(radius >= 0)) return;
  const double qlo[3] = {q[0] - radius, q[1] - radius, q[2] - radius}, qhi[3] = {q[0] + radius, q[1] + radius, q[2] + radius};
  int64_t a[3], b[3];
  if (!cellRange(qlo, qhi, a, b)) return;  // the ball misses the grid (or q is NaN)
  const double r2 = radius * radius;
  forCells(a, b, [&](const Cell& cc) {
    for (uint32_t o = cc.begin; o < cc.end; ++o) {
      const double* p = &sortedPos_[3 * size_t(o)];
      const double dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
      const double d2 = dx * dx + dy * dy + dz * dz;
      if (d2 <= r2) out.emplace_back(d2, order_[o]);
    }
  });
  if (ordered) std::sort(out.begin(), out.end());
}

bool GridKnn::cellRange(const double lo[3], const double hi[3], int64_t a[3], int64_t b[3]) const {
  for (int k = 0; k < 3; ++k) {
    const double l = std::floor((lo[k] - lo_[k]) / cell_), h = std::floor((hi[k] - lo_[k]) / cell_);
    if (!(h >= 0 && l <= double(dims_[k] - 1))) return false;
    a[k] = l < 0 ? 0 : int64_t(l);
    b[k] = h > double(dims_[k] - 1) ? dims_[k] - 1 : int64_t(h);
  }
  return true;
}

void GridKnn::cellsMeeting(const double lo[3], const double hi[3], std::vector<uint32_t>& out) const {
  out.clear();
  if (n_ == 0) return;
  int64_t a[3], b[3];
  if (!cellRange(lo, hi, a, b)) return;
  forCells(a, b, [&](const Cell& cc) { out.insert(out.end(), order_.begin() + cc.begin, order_.begin() + cc.end); });
}

void GridKnn::query(size_t i, int k, std::vector<int>& ind, std::vector<double>& d2) const {
  ind.clear(), d2.clear();
  if (i >= n_ || k <= 0) return;
  int64_t c[3];
  coords(i, c);
  Candidates cand;
  gather(c, 1, cand);
  std::vector<std::pair<double, uint32_t>> best;
  nearest(i, c, cand, k, best);
  for (const auto& e : best) ind.push_back(int(e.second)), d2.push_back(e.first);
}

}  // namespace sa
