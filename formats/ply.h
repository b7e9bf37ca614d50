// Streaming PLY reader: ascii, binary_little_endian and binary_big_endian; any property order
// and type; normals (nx ny nz) and colours (red green blue / r g b / diffuse_*) when present;
// `intensity`, `confidence` and `classification` kept as attributes;
// `face` lists fan-triangulated; `tristrips` decoded (-1 restarts); every other element
// (range_grid, ...) skipped. Memory is bounded by the batch size, not the file size.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "formats/points.h"

namespace sa {

struct PlyProperty {
  std::string name;
  int type = 0;       // PlyType
  bool isList = false;
  int countType = 0;  // PlyType of the list count
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

enum class PlyFormat { kAscii, kBinaryLittle, kBinaryBig };

struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
  std::vector<std::string> warnings;  // unknown header lines that were skipped
  std::vector<std::string> objInfo;
  uint64_t headerBytes = 0;
  uint64_t vertexCount = 0;
  bool hasNormals = false, hasColors = false;
  // scalar `intensity`, `confidence`, `classification` properties
  bool hasIntensity = false, hasConfidence = false, hasClassification = false;
  bool hasFaces = false;  // a face or tristrips element with entries
};

struct PlyReadOptions {
  size_t batchPoints = kDefaultBatchPoints;
  bool readFaces = true;
  // Range scans (Stanford/Cyberware PLY): triangulate the `range_grid` element, 2 triangles
  // per 2x2 block of grid cells that all hold a sample, using the `num_cols` obj_info.
  // Triangles are delivered through onTriangles; consumers filter long edges.
  bool rangeGridTriangles = false;
};

// Parses only the header (cheap) and validates the counts against the file size.
Result<PlyHeader> readPlyHeader(const std::string& path);

// Streams the whole file into `sink`. `header` (optional) receives the parsed header.
Status readPly(const std::string& path, const PlyReadOptions& options, BatchSink& sink,
               PlyHeader* header = nullptr);

}  // namespace sa
