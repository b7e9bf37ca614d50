// Google Draco (.drc) point clouds and meshes, read and written through libdraco. Attributes:
// position, normal, colour, and generic attributes named (attribute metadata "name")
// intensity, confidence and classification. Draco stores positions as 32-bit floats: for
// georeferenced data the writer stores them relative to an origin it records in the file's
// metadata ("scanatlas_origin", 3 doubles), which the reader adds back. A .drc file is one
// compressed block: the child reads and decodes it whole (memory there: the file plus the
// decoded cloud); this process receives it in batches.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "formats/points.h"

namespace sa {

struct DracoInfo {
  uint64_t points = 0, triangles = 0;
  bool hasNormals = false, hasColors = false;
  bool hasIntensity = false, hasConfidence = false, hasClassification = false;
  bool shifted = false;  // positions carry a scanatlas_origin
};

Result<DracoInfo> readDracoInfo(const std::string& path);
// Points in Draco's point order; triangles (meshes) by point index when readTriangles.
// libdraco is not hardened against hostile files (fuzzing found small files that make it
// allocate gigabytes), so both calls decode in a child process under an address-space limit
// and receive the points over a pipe; a decoder crash or exhausted limit is a bad-input error.
// `info`, when given, receives the description readDracoInfo gives, from the same decode.
Status readDraco(const std::string& path, size_t batchPoints, bool readTriangles, BatchSink& sink,
                 DracoInfo* info = nullptr);
// The same without the child process: for the fuzzer, which needs the decoder's coverage.
Status readDracoInProcess(const std::string& path, size_t batchPoints, bool readTriangles, BatchSink& sink);

struct DracoWriteOptions {
  int positionBits = 16;  // quantization of positions; 0 = lossless 32-bit floats
  int normalBits = 10;
  int speed = 5;          // Draco's 0 (smallest) .. 10 (fastest)
};

// Collects every batch, then encodes one point cloud, or one mesh when triangles came in
// (Draco needs all points at once).
class DracoWriter : public BatchSink {
 public:
  explicit DracoWriter(DracoWriteOptions opt) : opt_(opt) {}
  Status onPoints(const PointBatch& b) override;
  Status onTriangles(const uint32_t* idx, size_t count) override {
    tris_.insert(tris_.end(), idx, idx + 3 * count);
    return Status::ok();
  }
  uint64_t triangles() const { return tris_.size() / 3; }
  // Encodes and writes atomically; returns the file size.
  Result<uint64_t> write(const std::string& path, bool* shifted = nullptr);
  uint64_t points() const { return all_.size(); }

 private:
  DracoWriteOptions opt_;
  PointBatch all_;
  std::vector<uint32_t> tris_;
  bool first_ = true;
};

}  // namespace sa
