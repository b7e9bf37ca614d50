// Triangle path: which cells rasterize each triangle, and how far each cell's tile reaches.
// Neighbouring cells share the triangles that span their border: a triangle is rasterized by
// the cells of its vertices that can hold it (its face within the octree's angle of their W),
// and each such cell's extent grows to contain the part of the triangle nearer its vertex (the
// three parts tile the triangle; when a vertex's cell cannot hold it, the others hold all of it).
// The shared triangles are the overlap between cells, so a ray crossing the surface near a
// border meets it in at least one of them: no pinholes, and no foreign surface in a tile's
// margin. Large triangles (sampled with kChunkSurfaceSample points a lattice step apart) go to
// the cells of their samples too and need no growth: their cells' tiles reach a step past them.
#pragma once
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "common/error.h"

namespace sa {

struct CellExtent {
  Eigen::Vector3d origin, u, v, w;  // the cell's frame (relative to the pack origin)
  double ext[6];                    // its points' extents in the frame (uMin uMax vMin vMax wMin wMax); may grow
};

struct TriangleCellInput {
  const std::vector<double>* vertexPos = nullptr;     // xyz per vertex, relative to the pack origin
  const std::vector<uint32_t>* vertexCell = nullptr;  // the cell of each vertex (UINT32_MAX: none)
  const std::vector<std::pair<uint32_t, uint32_t>>* sampleCells = nullptr;  // (triangle, cell), sorted
  std::string trianglePath;  // u32 vertex-index triples
  // A cell holds a triangle whose face normal is within acos(minCos) of its W (the rasterizer
  // drops the others: edge-on or facing away, they are not part of its height field).
  double minCos = 0;
};

// Per vertex, the largest angle (radians) between its normal (vertexNormal, area-weighted, not
// necessarily unit) and the faces around it: the octree's height-field test must hold for the
// faces, not only for their average (a crease's vertex normal can pass where one of its faces
// faces away from W; then none of the cells of its vertices can hold that face: a hole).
Status vertexNormalCones(const std::string& trianglePath, const std::vector<double>& vertexPos,
                         const std::vector<float>& vertexNormal, std::vector<float>& cone);

// Appends (triangle, cell) pairs to out, sorted by triangle; grows cells' extents.
Status assignTrianglesToCells(const TriangleCellInput& in, std::vector<CellExtent>& cells,
                              std::vector<std::pair<uint32_t, uint32_t>>& out);

}  // namespace sa
