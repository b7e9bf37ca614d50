// OBJ, OFF and STL (ascii and binary) meshes through OpenMesh, for the triangle path of pack.
// OpenMesh reads a mesh whole (no streaming) and aborts on an assertion for some malformed OBJ
// files (found by fuzzing), so it runs in a child process (formats/isolate.h) that sends the
// vertices and triangles back in batches; an OFF header's counts are checked first.
#pragma once
#include <string>

#include "formats/points.h"

namespace sa {

// InputSet counts vertices and triangles from what readMesh delivers (it records the stream).
// Vertices in one or more batches, then the triangles (polygons fan-triangulated).
Status readMesh(const std::string& path, size_t batchPoints, bool readTriangles, BatchSink& sink);
// The same in this process: for the fuzzer, which needs OpenMesh's coverage.
Status readMeshInProcess(const std::string& path, size_t batchPoints, bool readTriangles, BatchSink& sink);

}  // namespace sa
