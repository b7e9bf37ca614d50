// PCL's PCD format (v0.5-0.7): ascii, binary and binary_compressed, read through PCL's
// pcl::PCDReader. The header is validated here first, because PCL allocates POINTS x point
// size on reading the header and trusts the sizes it finds: a hostile header must be refused
// before PCL sees it. ascii and binary bodies stream in batches (PCL's readBodyASCII /
// readBodyBinary on one batch at a time); binary_compressed is one LZF block, which
// pcl::lzfDecompress inflates whole (memory: the decompressed cloud, then batches). Entries whose x, y or z is
// NaN (the invalid pixels of organized clouds) are skipped and counted, not reported as errors.
// PCL never parses the header: ascii and binary bodies go through its body readers with a
// cloud description built here, and binary_compressed through its LZF decompressor.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "formats/points.h"

namespace sa {

enum class PcdEncoding { kAscii, kBinary, kBinaryCompressed };

struct PcdField {
  std::string name;
  int size = 4;     // bytes per element: 1, 2, 4 or 8
  char type = 'F';  // I, U or F
  uint32_t count = 1;
  uint32_t offset = 0;  // byte offset in a point record
};

struct PcdHeader {
  std::vector<PcdField> fields;
  uint64_t width = 0, height = 0, points = 0;
  uint32_t pointStep = 0;
  uint64_t dataOffset = 0;  // first byte after the DATA line
  uint64_t headerLines = 0; // lines up to and including DATA (ascii errors count from here)
  PcdEncoding encoding = PcdEncoding::kAscii;
  bool hasNormals = false, hasColors = false, hasIntensity = false;
  bool organized() const { return height > 1; }
};

// Own header parse and validation against the file size (cheap; allocates nothing large).
Result<PcdHeader> readPcdHeader(const std::string& path);

// Streams the points. `holes` (optional) receives the number of NaN entries skipped.
Status readPcd(const std::string& path, size_t batchPoints, BatchSink& sink, uint64_t* holes = nullptr);

}  // namespace sa
