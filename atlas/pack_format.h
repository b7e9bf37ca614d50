// On-disk records of the pack file. docs/FORMAT.md is the specification; these structs match
// it byte for byte (little-endian hosts only; static_asserts pin the sizes).
#pragma once
#include <bit>
#include <cmath>
#include <cstdint>

namespace sa {

static_assert(std::endian::native == std::endian::little, "pack I/O assumes a little-endian host");

inline constexpr char kPackMagic[8] = {'S', 'C', 'A', 'N', 'H', 'F', 'A', '\0'};
inline constexpr uint32_t kPackVersion = 2;
inline constexpr uint32_t kByteOrderMark = 0x01020304u;
inline constexpr uint64_t kSectionAlign = 4096;

struct PackHeader {
  char magic[8];
  uint32_t version;
  uint32_t byteOrder;
  uint32_t sectionCount;
  uint32_t headerSize;
  uint64_t fileSize;
  uint64_t sectionTableOffset;
  uint32_t sectionTableCrc;
  uint8_t zero[20];
};
static_assert(sizeof(PackHeader) == 64);

struct SectionEntry {
  char id[4];
  uint32_t flags;
  uint64_t offset;
  uint64_t size;
  uint32_t crc;
  uint32_t zero;
};
static_assert(sizeof(SectionEntry) == 32);

enum PackFlags : uint32_t { kPackHasColor = 1, kPackFromTriangles = 2, kPackNormalsEstimated = 4, kPackHasNormals = 8 };

// Where PackMeta::up came from.
enum UpSource : uint32_t { kUpUnknown = 0, kUpGiven = 1, kUpConvention = 2, kUpFromData = 3 };

struct PackMeta {
  double origin[3];
  double boundsMin[3];
  double boundsMax[3];
  double texelSize;
  double sampleSpacing;
  uint64_t sourcePoints;
  uint64_t skippedPoints;
  uint64_t sourceTriangles;
  uint32_t cellCount;
  uint32_t pageWidth;
  uint32_t pageCount;
  uint32_t flags;
  uint32_t maxDepth;
  uint32_t chunkCount;
  uint64_t texelsUsed;
  double seconds[6];  // count, distribute, normals+octree, heightmaps, write, total
  uint64_t inputHash;  // XXH3 of the input files' bytes and the pack options (0: unknown)
  double up[3];        // world up axis (unit; zero = unknown)
  uint32_t pageHeight;
  uint32_t upSource;   // UpSource
  uint64_t outliersRemoved;
  uint8_t zero[16];
};
static_assert(sizeof(PackMeta) == 256);

enum CellFlags : uint8_t { kCellForced = 1, kCellDegenerate = 2 };

struct CellRecord {
  double origin[3];
  double u[3];
  double v[3];
  double w[3];
  double box[6];  // uMin, uMax, vMin, vMax, wMin, wMax
  uint32_t page;
  uint32_t tileX;
  uint32_t tileY;
  uint16_t tileW;
  uint16_t tileH;
  uint32_t pointCount;
  uint8_t level;
  uint8_t flags;
  uint16_t zero;
};
static_assert(sizeof(CellRecord) == 168);

// Height encoding (FORMAT.md): 0 = not covered, 1..65535 spans [wMin, wMax].
inline uint16_t encodeHeight(double w, double wMin, double wMax) {
  double t = wMax > wMin ? (w - wMin) / (wMax - wMin) : 0.5;
  t = t < 0 ? 0 : (t > 1 ? 1 : t);
  return static_cast<uint16_t>(1 + static_cast<uint32_t>(t * 65534.0 + 0.5));
}
inline double decodeHeight(uint16_t k, double wMin, double wMax) {
  return wMin + (static_cast<double>(k) - 1.0) / 65534.0 * (wMax - wMin);
}

// Normal encoding (FORMAT.md): hemi-octahedral, in the cell frame, two bytes.
inline void encodeNormal(double nu, double nv, double nw, uint8_t out[2]) {
  if (nw < 0) nw = 0;
  double s = (nu < 0 ? -nu : nu) + (nv < 0 ? -nv : nv) + nw;
  double pu = 0, pv = 0;
  if (s > 0) {
    pu = nu / s;
    pv = nv / s;
  }
  const double e0 = (pu + pv) * 127.5 + 127.5, e1 = (pu - pv) * 127.5 + 127.5;
  out[0] = static_cast<uint8_t>(e0 < 0 ? 0 : (e0 > 255 ? 255 : e0 + 0.5));
  out[1] = static_cast<uint8_t>(e1 < 0 ? 0 : (e1 > 255 ? 255 : e1 + 0.5));
}
// Writes the unit normal (frame components) of an encoded texel.
inline void decodeNormal(const uint8_t in[2], double n[3]) {
  const double e0 = in[0] / 127.5 - 1, e1 = in[1] / 127.5 - 1;
  const double tu = (e0 + e1) / 2, tv = (e0 - e1) / 2;
  n[0] = tu;
  n[1] = tv;
  n[2] = 1 - (tu < 0 ? -tu : tu) - (tv < 0 ? -tv : tv);
  const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  for (int a = 0; a < 3; ++a) n[a] /= len;
}

}  // namespace sa
