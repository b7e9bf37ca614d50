// Point path: the samples of neighbouring cells that continue a cell's surface into its tile's
// margin. Each cell's height map reaches the coverage radius past its own points; built from
// its own points alone, two neighbouring cells' surfaces would each be extrapolated there and
// a ray crossing the surface near their border could pass between them (a pinhole). With the
// neighbours' samples in the margin, both cells reconstruct the border from the same points.
#pragma once
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

namespace sa {

class MarginFinder {
 public:
  // pos: the chunk's points, xyz interleaved (kept by reference); nrm: their unit normals.
  // spacing: their area spacing when the caller knows it (estimated otherwise); it sizes the
  // neighbour grid, which changes how fast the queries are, not what they find.
  MarginFinder(const double* pos, const float* nrm, size_t n, double spacing = 0);
  ~MarginFinder();

  struct Cell {
    Eigen::Vector3d origin, u, v, w;
    double ext[6];              // the cell's own points' extents in its frame
    uint32_t first, count;      // its points: [first, first + count) of the chunk
  };
  // Points outside the cell within `radius` of one of its points, inside its extents grown by
  // `radius` in u and v, facing its +W side (normal . w > minCos); appended to `out`.
  void find(const Cell& c, double radius, double minCos, std::vector<uint32_t>& out) const;

  // The smooth normal field of the chunk's points at each of the m points xyz: their normals
  // averaged with weights (1 - (d/radius)^2)^2 over every point within `radius` (3-D) whose
  // normal agrees with hints[i] (dot > 0.5). A function of position only: two cells asking at
  // the same place get the same normal, so shading is continuous across their border. Where no
  // point is near, out[i] = hints[i]. The weighted sums are exact (fixed point), so the result
  // does not depend on the order in which the points are found.
  void normalField(const double* xyz, const float* hints, size_t m, double radius, float* out) const;

  // The same field at the covered texels of one tile, given on its texel grid (width x height,
  // row-major): x, y, z each texel's surface point (world), hx, hy, hz its hint, zero where the
  // texel is not covered. The hints of the covered texels are replaced by the field, to the bit
  // what normalField gives there. The chunk's points near the tile are gathered once and each
  // adds its weight to the texels within its reach, instead of a grid query per texel.
  struct TexelFrame {
    Eigen::Vector3d origin, u, v;  // the tile's frame (u, v orthonormal)
    double u0, v0, du, dv;         // texel (i, j) has its centre at u0 + (i + 0.5) du, v0 + (j + 0.5) dv
    int width, height;
  };
  struct TileTexels {
    std::vector<double> x, y, z;
    std::vector<float> hx, hy, hz;
    explicit TileTexels(size_t n) : x(n, 0.0), y(n, 0.0), z(n, 0.0), hx(n, 0.f), hy(n, 0.f), hz(n, 0.f) {}
  };
  void tileField(const TexelFrame& tile, double radius, TileTexels& texels) const;

 private:
  struct Index;
  const double* pos_;
  const float* nrm_;
  std::unique_ptr<Index> index_;
};

}  // namespace sa
