// Height maps from points by pull-push interpolation (Gortler et al. 1996, as used by Lu,
// Low & Zheng §3.2.1), with a coverage mask: a texel is covered only if a sample lies within
// `coverageRadius` of its centre, so holes and scan edges stay open. Also the triangle path:
// exact rasterization of a mesh into the height map.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

namespace sa {

// Tile geometry in the cell's frame: texel (i, j) has its centre at
// (u0 + (i + 0.5) * du, v0 + (j + 0.5) * dv); heights encode [wMin, wMax] (FORMAT.md).
struct TileGrid {
  int width = 1, height = 1;
  double u0 = 0, v0 = 0, du = 1, dv = 1;
  double wMin = 0, wMax = 1;
};

struct TileOutput {
  std::vector<uint16_t> heights;  // width * height; 0 = not covered
  std::vector<uint8_t> rgba;      // width * height * 4 when colours were given
  size_t covered = 0;
};

// Samples in frame coordinates (u, v, w); rgb (3 per sample) may be null.
void pullPushTile(const TileGrid& g, const double* u, const double* v, const double* w, const uint8_t* rgb,
                  size_t n, double coverageRadius, TileOutput& out);

// Triangles in frame coordinates (9 doubles each: u, v, w per vertex). Keeps the largest w
// per texel (the surface seen from the +W side) within [wMin - slack, wMax + slack].
void rasterizeTile(const TileGrid& g, const double* tris, size_t triangleCount, double slack, TileOutput& out);

}  // namespace sa
