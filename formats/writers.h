// Point writers for `scanatlas convert`: binary little-endian PLY (double positions, so
// georeferenced coordinates keep their precision) and text (XYZ/TXT space-separated, CSV
// comma-separated, with a header line of column names that ScanAtlas's text reader and most
// tools recognise). Both stream: memory does not depend on the point count. Output goes to a
// temporary file beside the target, renamed on finish(); nothing half-written is left behind.
#pragma once
#include <memory>
#include <string>

#include "common/fileio.h"
#include "formats/points.h"

namespace sa {

// Which optional attributes a writer emits (decided before the first batch).
struct PointLayout {
  bool normals = false, colors = false, intensity = false, confidence = false, classification = false;
};

class PointWriter : public BatchSink {
 public:
  virtual Status finish() = 0;  // completes and renames the file into place
  virtual uint64_t written() const = 0;
};

Result<std::unique_ptr<PointWriter>> openPlyWriter(const std::string& path, const PointLayout& layout);
Result<std::unique_ptr<PointWriter>> openTextWriter(const std::string& path, const PointLayout& layout, char delimiter);

}  // namespace sa
