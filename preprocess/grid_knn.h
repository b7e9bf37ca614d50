// Exact k-nearest-neighbour queries of every point of a chunk against the chunk itself, on a
// uniform grid instead of a kd-tree (issue "Scale": FLANN's per-point search was ~40 % of packing
// a LAS without normals). Scan points lie on surfaces, so with a cell about as wide as the k-th
// neighbour's distance the 3x3x3 block around a point's cell holds its k nearest neighbours and
// a few dozen more; the block is gathered once per cell and shared by every point in it. A point
// whose k-th candidate lies farther than the block guarantees (sparse fringes, outliers) widens
// its own search ring by ring until the answer is exact.
//
// Results equal a brute-force search: the k smallest squared distances, ties broken by the
// lower index, so a chunk's neighbourhoods do not depend on thread scheduling.
#pragma once
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <vector>

#include "common/raw_vector.h"

namespace sa {

// The bounds of n xyz-interleaved points, on every core (min and max are exact in any order);
// lo = +inf, hi = -inf when n is 0.
void pointBounds(const double* pos, size_t n, double lo[3], double hi[3]);

class GridKnn {
 public:
  // pos: n xyz-interleaved points (kept by reference: must outlive the index). cell: the grid's
  // cell side (> 0; widened where the extent would need more than 2^20 cells per axis).
  GridKnn(const double* pos, size_t n, double cell);
  GridKnn(GridKnn&&) = default;
  GridKnn(const GridKnn&) = delete;  // would share the positions it sorted
  GridKnn& operator=(const GridKnn&) = delete;

  // This grid, its points renumbered in its order (point k is the caller's order()[k], now in
  // orig): the grid GridKnn(src, n, cell) builds over src, the positions in that order, without
  // sorting them again. src and orig are the caller's; src is kept by reference.
  GridKnn inOrder(RawVector<double>& src, std::vector<uint32_t>& orig) &&;

  // A cell side for k neighbours on a surface sampled with area spacing `spacing` (the side
  // of the area per point): the k-th neighbour usually lies within it.
  static double cellFor(double spacing, int k);

  // Calls fn(i, ind, d2, m) for every point i, on every core: ind/d2 its m = min(k, n) nearest
  // points (the point itself first unless it has duplicates of lower index) and their squared
  // distances, ascending. fn runs concurrently for different points.
  using Visit = std::function<void(size_t i, const int* ind, const double* d2, int m)>;
  void forEach(int k, const Visit& fn) const;

  // Every point within `radius` of q (any position, inside the grid or not) as (d2, index),
  // ascending (unordered: in the grid's order, for callers that only collect). Thread-safe.
  void within(const double* q, double radius, std::vector<std::pair<double, uint32_t>>& out, bool ordered = true) const;

  // Per point (indexed like pos): the t-th smallest value (0: the smallest) over the points of
  // the 3x3x3 block of cells around its cell, or -infinity where the block holds t points or
  // fewer. Any more than t of its neighbours within blockReach(i) have their t-th smallest at
  // least this.
  RawVector<float> blockRank(const float* value, size_t t) const;
  // How far point i lies from the outside of the 3x3x3 block of cells around its cell (infinite
  // where the block reaches the grid's edge on both sides of every axis): every point within
  // that distance of it is in the block.
  double blockReach(size_t i) const {
    int64_t c[3];
    coords(i, c);
    return reach(pos_ + 3 * i, c, 1);
  }

  // Every point in the cells that meet the box [lo, hi] (a superset of the points in the box),
  // indices in the grid's order.
  void cellsMeeting(const double lo[3], const double hi[3], std::vector<uint32_t>& out) const;

  // The same for one point (tests; the slow path).
  void query(size_t i, int k, std::vector<int>& ind, std::vector<double>& d2) const;

  double cell() const { return cell_; }
  // Point indices in the grid's order: by cell, cells in Morton order (close in space, mostly
  // close in this order), within a cell by index.
  const std::vector<uint32_t>& order() const { return order_; }

 private:
  struct Cell {
    uint64_t key;
    uint32_t begin, end;  // into order_
  };
  int64_t findCell(uint64_t key) const;
  // The cells [a, b] that meet the box [lo, hi]; false when it misses the grid (or is NaN).
  bool cellRange(const double lo[3], const double hi[3], int64_t a[3], int64_t b[3]) const;
  // Distance from p (a point of cell c) to the outside of the block of cells within `ring` of c.
  double reach(const double* p, const int64_t c[3], int ring) const;
  uint64_t keyOf(int64_t x, int64_t y, int64_t z) const;
  void coords(size_t i, int64_t c[3]) const;
  struct Candidates {
    std::vector<uint32_t> index;
    std::vector<double> x, y, z;  // their positions, one array per axis (the distances vectorize)
    std::vector<double> d2;       // scratch: their squared distances to the point asked about
    std::vector<uint32_t> near;   // scratch: the candidates within the bound
    std::vector<uint16_t> bucket; // scratch: their histogram buckets
  };
  // visit(cell) for every non-empty cell of the block [a, b] (cell coordinates, inclusive).
  template <class F>
  void forCells(const int64_t a[3], const int64_t b[3], F visit) const;
  // Candidates in the cube of cells within `ring` of cell c (ring 1: 3x3x3).
  void gather(const int64_t c[3], int ring, Candidates& out) const;
  // bound2: a guess at the k-th squared distance (a neighbour's k-th distance plus the distance
  // to it); candidates beyond it are skipped unless that leaves fewer than k. Any value gives the
  // exact answer; a good one only makes it faster.
  bool select(const double* p, Candidates& from, int k, double b2, std::vector<std::pair<double, uint32_t>>& best) const;
  // c: point i's cell (coords).
  void nearest(size_t i, const int64_t c[3], Candidates& cand, int k, std::vector<std::pair<double, uint32_t>>& best,
               double bound2 = std::numeric_limits<double>::infinity()) const;

  const double* pos_;
  size_t n_;
  double cell_;
  double lo_[3];
  int64_t dims_[3];
  std::vector<uint32_t> order_;  // point indices sorted by cell
  RawVector<double> sorted_;     // their positions in that order (resized without zeroing: the loop filling it touches it first)
  const double* sortedPos_;      // sorted_, or pos_ where the points are in the grid's order
  std::vector<Cell> cells_;
  struct Slot {
    uint64_t key;  // the cell's key beside its index: a probe reads one line, not two
    int64_t cell;  // index into cells_, or -1
  };
  std::vector<Slot> table_;  // open addressing
  uint64_t mask_ = 0;
};

}  // namespace sa
