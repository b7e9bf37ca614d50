// Text point clouds: XYZ, PTS and CSV (own reader). Columns come from --columns
// (x,y,z,nx,ny,nz,r,g,b,i,c,confidence; '_' skips a column), from a header line of names, or from the
// column count (3: x y z; 4: x y z i; 6: x y z r g b; 7: x y z i r g b, as PTS; 9: x y z r g b
// nx ny nz). The delimiter (comma, semicolon, tab, spaces) is detected from the first data
// line; a PTS count line and a header line are skipped. Errors name the line and column.
#pragma once
#include <string>
#include <vector>

#include "formats/points.h"

namespace sa {

inline constexpr int kTextRoles = 12;

struct TextLayout {
  // per column: 0..2 xyz, 3..5 normal, 6..8 rgb, 9 intensity, 10 classification, 11 confidence, -1 skip
  std::vector<int> roles;
  char delimiter = ' ';    // ' ' = any run of spaces and tabs
  uint64_t dataLines = 0;  // lines holding points
  bool hasNormals = false, hasColors = false;
  bool hasIntensity = false, hasClassification = false, hasConfidence = false;
};

// Scans the file once (line count, delimiter, header) and settles the columns.
Result<TextLayout> readTextLayout(const std::string& path, const std::string& columns);
Status readText(const std::string& path, const TextLayout& layout, size_t batchPoints, BatchSink& sink);

}  // namespace sa
