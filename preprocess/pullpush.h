// Height maps from points: the samples are splatted with a smooth kernel sized to the sample
// spacing, holes between them are filled by pull-push interpolation (Gortler et al. 1996, as
// used by Lu, Low & Zheng §3.2.1), and a coverage mask decided in 3-D keeps holes, scan edges
// and height jumps open. Also the triangle path: exact rasterization of a mesh into the map.
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
  // The cell's axes U, V, W in world coordinates (rows): output normals are stored in world
  // coordinates (FORMAT.md).
  double frame[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  void toWorld(const double f[3], double w[3]) const {
    for (int a = 0; a < 3; ++a) w[a] = f[0] * frame[a] + f[1] * frame[3 + a] + f[2] * frame[6 + a];
  }
};

struct TileOutput {
  std::vector<uint16_t> heights;  // width * height; 0 = not covered
  double wMin = 0, wMax = 0;      // the height range the heights encode
  std::vector<uint8_t> normals;   // width * height * kNormalBytes (encodeNormal, world) when normals were given
  std::vector<uint8_t> rgba;      // width * height * 4 when colours were given
  size_t covered = 0;
  // The normals' and colours' pyramid payloads, made where snapNormals and snapColours snapped
  // them (snapToPyramid), for the page coder (PackWriter::writeTile); empty otherwise. Stale once
  // the texels change.
  std::vector<uint8_t> normalPyramid, rgbaPyramid;
};

// Samples of one cell in its frame. normal (3 per sample, frame components, unit), rgb (3 per
// sample) and scale (1 per sample) may be null.
struct TileSamples {
  const double* u = nullptr;
  const double* v = nullptr;
  const double* w = nullptr;
  const float* normal = nullptr;
  const uint8_t* rgb = nullptr;
  // The sample's local spacing over the pack's, as far as the caller lets it grow (pipeline.cpp,
  // sampleScale): its splat and coverage radii are the options' times this (at least 1), so a
  // region seen by one scan of several, or sampled sparsely, is not peppered with holes.
  const float* scale = nullptr;
  size_t n = 0;
};

struct SplatOptions {
  // Radius of the splat kernel (world units): each sample spreads over the texels within it
  // with weight (1 - (d/r)^2)^2, so the surface between samples is a smooth weighted average
  // rather than a bump per sample. 0: bilinear onto the four nearest texels.
  double splatRadius = 0;
  // A texel is covered when its reconstructed surface point lies within this 3-D distance of
  // a sample.
  double coverageRadius = 0;
  // Then a gap the samples left inside the tile is covered where every texel of it lies within
  // this 3-D distance of a covered texel (world units; 0: off): randomly spaced samples leave
  // such gaps where none happens to fall within the coverage radius, and a far view shows them
  // as background pinholes on a closed surface. Gaps that reach the tile's border stay open.
  double gapReach = 0;
  // Widen [wMin, wMax] to hold every covered texel's height (else heights outside are clamped,
  // and a clamped height is a flat floor or ceiling a ray would hit at the box's face).
  bool fitHeightRange = false;
};

void pullPushTile(const TileGrid& g, const TileSamples& s, const SplatOptions& opt, TileOutput& out);

// Rounds the covered heights' codes to multiples of the largest power of two whose world step is
// at most maxStep (FORMAT.md): a height moves by at most maxStep / 2 (maxStep at the range's top,
// rounded down to stay inside it). The bits below hold nothing a render resolves, and with them
// zero the coded pages' prediction residuals are multiples of the step too. Returns the step in
// codes (1: nothing changed).
uint32_t roundHeights(TileOutput& out, double maxStep);

// Sets each covered normal of the tile to its rebuild from the coarser levels of the page
// coder's pyramid (snapToPyramid) where that moves it by at most maxDegrees; likewise each
// colour where no channel moves by more than maxLevels. The coder then stores such a texel as
// a zero difference. The normals are a smooth field over several sample spacings,
// the texels a fraction of one. Return the texels changed.
size_t snapNormals(TileOutput& out, int width, int height, double maxDegrees);
size_t snapColours(TileOutput& out, int width, int height, int maxLevels);

// Triangles in frame coordinates (9 doubles each: u, v, w per vertex). Triangles facing +W
// (counter-clockwise seen from +W) with a face normal whose W component is over minCos are
// rasterized, keeping the largest w per texel (the surface seen from the +W side) within
// [wMin - slack, wMax + slack]. vertexNormals (may be null): 9 floats per triangle, its vertices'
// unit normals in world coordinates, interpolated into the texels' stored normals.
void rasterizeTile(const TileGrid& g, const double* tris, size_t triangleCount, double slack, double minCos,
                   const float* vertexNormals, TileOutput& out);

}  // namespace sa
