// ASPRS LAS 1.0-1.4, point data formats 0-10 (own reader: Debian ships no LAS library).
// Positions are X*scale + offset in double; intensity and classification kept as attributes; RGB (formats 2, 3, 5, 7, 8, 10) scaled to 8 bits,
// or taken as is when the file stores 8-bit values in its 16-bit fields (as autzen does).
// LAZ (compressed) is refused with a message on how to decompress it.
#pragma once
#include <cstdint>
#include <string>

#include "formats/points.h"

namespace sa {

struct LasHeader {
  int versionMajor = 1, versionMinor = 0;
  int pointFormat = 0;
  uint32_t recordLength = 0;
  uint64_t pointCount = 0;
  uint64_t dataOffset = 0;
  double scale[3] = {1, 1, 1}, offset[3] = {0, 0, 0};
  double min[3] = {0, 0, 0}, max[3] = {0, 0, 0};
  bool hasColor = false;
  bool color8bit = false;  // 8-bit values stored in the 16-bit fields
  // The point format has RGB fields but every sampled record holds the same values (all zero,
  // typically): hasColor is then false and these are the values.
  bool colorConstant = false;
  uint16_t constantColor[3] = {0, 0, 0};
  int colorOffset = -1;    // byte offset of RGB in the record
};

// Reads and validates the header; samples the colours to decide their scaling.
Result<LasHeader> readLasHeader(const std::string& path);
Status readLas(const std::string& path, size_t batchPoints, BatchSink& sink, LasHeader* header = nullptr);

}  // namespace sa
