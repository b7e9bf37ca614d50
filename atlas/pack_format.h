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

// Normal encoding (FORMAT.md): octahedral, world space, two unsigned components of
// kNormalBytes / 2 bytes each. In world space the same normal gets the same bits in every cell,
// so neighbouring cells' shading agrees where their tiles overlap; 16-bit components round
// nearly equal normals alike (8 bits: 0.45 degree steps, a seam in every close-up: the dragon's
// seam ratio at the close-up was 3.6 with 8 bits, 1.8 with 16).
inline constexpr int kNormalBytes = 4;
inline constexpr double kNormalMax = kNormalBytes == 2 ? 255.0 : 65535.0;  // the largest component value
// Components are rounded to multiples of kNormalStep: 10 significant bits, steps of at most
// 0.11 degree (invisible: a grey level is about 0.3 degree at 45 degrees of incidence), while the
// 6 bits below hold only the normals' noise, which no lossless coder shrinks (bunny and dragon
// pages' normals 43-46 % smaller; seam ratios and normal errors unchanged to 0.002 degree).
inline constexpr double kNormalStep = 64;
// std::round of a value in [0, 2^52), by truncation: the same result (halves away from zero),
// without the library call the baseline x86-64 build makes for std::round. Other values go to
// std::round.
inline double roundNonNegative(double v) {
  if (!(v >= 0 && v < 4503599627370496.0)) return std::round(v);
  const double t = static_cast<double>(static_cast<int64_t>(v));  // v - t is exact
  return t + static_cast<double>(v - t >= 0.5);  // no branch: the fraction is noise
}
// std::lround likewise.
inline long lroundNonNegative(double v) {
  if (!(v >= 0 && v < 4503599627370496.0)) return std::lround(v);
  return static_cast<long>(roundNonNegative(v));
}
inline void encodeNormal(double x, double y, double z, uint8_t out[kNormalBytes]) {
  const double s = std::abs(x) + std::abs(y) + std::abs(z);
  double px = 0, py = 0;
  if (s > 0) {
    px = x / s;
    py = y / s;
    if (z < 0) {  // the lower half folds over the square's corners
      const double fx = (1 - std::abs(py)) * (px < 0 ? -1 : 1), fy = (1 - std::abs(px)) * (py < 0 ? -1 : 1);
      px = fx;
      py = fy;
    }
  }
  const double e[2] = {(px + 1) * kNormalMax / 2, (py + 1) * kNormalMax / 2};
  for (int k = 0; k < 2; ++k) {
    const double q = roundNonNegative(e[k] / kNormalStep) * kNormalStep;
    const uint32_t v = static_cast<uint32_t>(q < 0 ? 0 : (q > kNormalMax ? kNormalMax - kNormalStep + 1 : q));
    for (int b = 0; b < kNormalBytes / 2; ++b) out[k * kNormalBytes / 2 + b] = static_cast<uint8_t>(v >> (8 * b));
  }
}
// Writes the unit world normal of an encoded texel.
inline void decodeNormal(const uint8_t in[kNormalBytes], double n[3]) {
  double p[2];
  for (int k = 0; k < 2; ++k) {
    uint32_t v = 0;
    for (int b = 0; b < kNormalBytes / 2; ++b) v |= uint32_t(in[k * kNormalBytes / 2 + b]) << (8 * b);
    p[k] = v / kNormalMax * 2 - 1;
  }
  double z = 1 - std::abs(p[0]) - std::abs(p[1]), x = p[0], y = p[1];
  if (z < 0) {
    x = (1 - std::abs(p[1])) * (p[0] < 0 ? -1 : 1);
    y = (1 - std::abs(p[0])) * (p[1] < 0 ? -1 : 1);
  }
  const double len = std::sqrt(x * x + y * y + z * z);
  n[0] = x / len;
  n[1] = y / len;
  n[2] = z / len;
}

}  // namespace sa
