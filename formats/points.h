// Plain batch types every reader produces: one array per attribute, positions in double.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "common/error.h"

namespace sa {

struct PointBatch {
  std::vector<double> x, y, z;
  std::vector<float> nx, ny, nz;   // empty when the source has no normals
  std::vector<uint8_t> r, g, b;    // empty when the source has no colours
  std::vector<uint16_t> scan;      // scan index inside a scan set; empty for single files
  // Per-point scanner attributes, empty when the source has none: return strength (LAS
  // intensity, PLY `intensity`, PCD `intensity`), range-scan confidence (PLY `confidence`),
  // ASPRS class (LAS classification).
  std::vector<float> intensity, confidence;
  std::vector<uint8_t> classification;
  uint64_t firstIndex = 0;         // index of the first point of this batch in its file

  size_t size() const { return x.size(); }
  bool hasNormals() const { return !nx.empty(); }
  bool hasColors() const { return !r.empty(); }
  bool hasIntensity() const { return !intensity.empty(); }
  bool hasConfidence() const { return !confidence.empty(); }
  bool hasClassification() const { return !classification.empty(); }
  void clear() {
    x.clear(); y.clear(); z.clear(); nx.clear(); ny.clear(); nz.clear();
    r.clear(); g.clear(); b.clear(); scan.clear();
    intensity.clear(); confidence.clear(); classification.clear();
  }
};

// Receives batches from a reader. Called once per batch (never per point). Returning an
// error stops the reader, which returns that error.
class BatchSink {
 public:
  virtual ~BatchSink() = default;
  virtual Status onPoints(const PointBatch& batch) = 0;
  // Triangles as vertex-index triples (indices into the file's vertex element).
  virtual Status onTriangles(const uint32_t* indices, size_t triangleCount) {
    (void)indices; (void)triangleCount;
    return Status::ok();
  }
};

inline constexpr size_t kDefaultBatchPoints = 1 << 16;

}  // namespace sa
