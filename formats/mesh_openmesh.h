// OBJ, OFF and STL (ascii and binary) meshes through OpenMesh, for the triangle path of pack.
// OpenMesh reads a mesh whole (no streaming): memory grows with the mesh, as the README says.
#pragma once
#include <string>

#include "formats/points.h"

namespace sa {

struct MeshInfo {
  uint64_t vertices = 0, triangles = 0;
  bool hasNormals = false, hasColors = false;
};

Result<MeshInfo> readMeshInfo(const std::string& path);
// Vertices in one or more batches, then the triangles (polygons fan-triangulated).
Status readMesh(const std::string& path, size_t batchPoints, bool readTriangles, BatchSink& sink);

}  // namespace sa
