#include "formats/las.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "common/fileio.h"

namespace sa {
namespace {

template <class T>
T get(const uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

// Minimum record length and RGB offset of each point data format (LAS 1.4 R15, Table 7 ff.).
constexpr int kMinLength[11] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};
constexpr int kRgbOffset[11] = {-1, -1, 20, 28, -1, 28, -1, 30, 30, -1, 30};

}  // namespace

Result<LasHeader> readLasHeader(const std::string& path) {
  BufferedReader in;
  SA_RETURN_IF_ERROR(in.open(path, 1 << 16));
  uint8_t h[375] = {};
  const size_t got = std::min<uint64_t>(in.fileSize(), sizeof(h));
  if (got < 227 || !in.read(h, got)) return Status::badInput(path + ": too short for a LAS header (" + std::to_string(in.fileSize()) + " bytes)");
  if (std::memcmp(h, "LASF", 4) != 0) return Status::badInput(path + ": not a LAS file (no LASF signature at byte 0)");
  LasHeader L;
  L.versionMajor = h[24];
  L.versionMinor = h[25];
  if (L.versionMajor != 1 || L.versionMinor > 4)
    return Status::badInput(path + ": LAS version " + std::to_string(L.versionMajor) + "." + std::to_string(L.versionMinor) +
                            " is not supported (1.0 to 1.4)");
  const uint16_t headerSize = get<uint16_t>(h + 94);
  L.dataOffset = get<uint32_t>(h + 96);
  const uint8_t fmtByte = h[104];
  if (fmtByte & 0xC0)
    return Status::badInput(path + ": LAZ-compressed points (format byte " + std::to_string(fmtByte) +
                            ") are not supported; decompress first, e.g. 'laszip -i in.laz -o out.las' or "
                            "'pdal translate in.laz out.las'");
  L.pointFormat = fmtByte;
  if (L.pointFormat > 10) return Status::badInput(path + ": unknown point data format " + std::to_string(L.pointFormat));
  L.recordLength = get<uint16_t>(h + 105);
  if (L.recordLength < uint32_t(kMinLength[L.pointFormat]))
    return Status::badInput(path + ": point record length " + std::to_string(L.recordLength) + " is shorter than format " +
                            std::to_string(L.pointFormat) + " needs (" + std::to_string(kMinLength[L.pointFormat]) + ")");
  L.pointCount = get<uint32_t>(h + 107);
  if (L.versionMinor >= 4 && headerSize >= 375 && got >= 255) {
    const uint64_t n14 = get<uint64_t>(h + 247);
    if (n14 != 0) L.pointCount = n14;
  }
  for (int a = 0; a < 3; ++a) {
    L.scale[a] = get<double>(h + 131 + 8 * a);
    L.offset[a] = get<double>(h + 155 + 8 * a);
    L.max[a] = get<double>(h + 179 + 16 * a);
    L.min[a] = get<double>(h + 187 + 16 * a);
    if (!(L.scale[a] != 0) || !std::isfinite(L.scale[a]) || !std::isfinite(L.offset[a]))
      return Status::badInput(path + ": invalid scale or offset for axis " + std::to_string(a));
  }
  if (headerSize < 227 || L.dataOffset < headerSize || L.dataOffset > in.fileSize())
    return Status::badInput(path + ": offset to point data " + std::to_string(L.dataOffset) + " is outside the file");
  const uint64_t available = (in.fileSize() - L.dataOffset) / L.recordLength;
  if (L.pointCount > available)
    return Status::badInput(path + ": header declares " + std::to_string(L.pointCount) + " points but the file holds at most " +
                            std::to_string(available) + " (truncated or header corrupt)");
  L.colorOffset = kRgbOffset[L.pointFormat];
  L.hasColor = L.colorOffset >= 0;
  if (L.hasColor && L.pointCount > 0) {
    // Sample up to 4096 records spread over the file: all channels <= 255 means 8-bit colour;
    // every sample the same colour (all zero, typically) means no colour at all.
    uint16_t maxc = 0;
    bool varies = false;
    uint16_t first[3] = {0, 0, 0};
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) return Status::badInput(path + ": cannot reopen");
    std::vector<uint8_t> rec(L.recordLength);
    const uint64_t samples = std::min<uint64_t>(4096, L.pointCount);
    for (uint64_t k = 0; k < samples; ++k) {
      const uint64_t i = k * L.pointCount / samples;
      if (fseeko(f, off_t(L.dataOffset + i * L.recordLength), SEEK_SET) != 0 || std::fread(rec.data(), 1, rec.size(), f) != rec.size()) break;
      for (int c = 0; c < 3; ++c) {
        const uint16_t v = get<uint16_t>(rec.data() + L.colorOffset + 2 * c);
        maxc = std::max(maxc, v);
        if (k == 0) first[c] = v;
        varies |= v != first[c];
      }
    }
    std::fclose(f);
    L.color8bit = maxc <= 255;
    if (!varies) {
      L.hasColor = false;
      std::copy(first, first + 3, L.constantColor);
      L.colorConstant = true;
    }
  }
  return L;
}

Status readLas(const std::string& path, size_t batchPoints, BatchSink& sink, LasHeader* out) {
  auto hdr = readLasHeader(path);
  if (!hdr) return hdr.status();
  const LasHeader& L = *hdr;
  if (out) *out = L;
  BufferedReader in;
  SA_RETURN_IF_ERROR(in.open(path));
  if (!in.skip(L.dataOffset)) return Status::badInput(path + ": cannot seek to the point data");
  std::vector<uint8_t> buf;
  PointBatch b;
  uint64_t done = 0;
  while (done < L.pointCount) {
    const size_t n = size_t(std::min<uint64_t>(batchPoints, L.pointCount - done));
    buf.resize(n * L.recordLength);
    if (!in.read(buf.data(), buf.size()))
      return Status::badInput(path + ": unexpected end of file at byte " + std::to_string(in.offset()) + " in point " +
                              std::to_string(done));
    b.clear();
    b.firstIndex = done;
    b.x.resize(n); b.y.resize(n); b.z.resize(n);
    if (L.hasColor) { b.r.resize(n); b.g.resize(n); b.b.resize(n); }
    b.intensity.resize(n);
    b.classification.resize(n);
    // Classification: 5 bits of byte 15 in formats 0-5, the whole byte 16 in formats 6-10.
    const bool extended = L.pointFormat >= 6;
    for (size_t i = 0; i < n; ++i) {
      const uint8_t* p = buf.data() + i * L.recordLength;
      b.x[i] = get<int32_t>(p) * L.scale[0] + L.offset[0];
      b.y[i] = get<int32_t>(p + 4) * L.scale[1] + L.offset[1];
      b.z[i] = get<int32_t>(p + 8) * L.scale[2] + L.offset[2];
      b.intensity[i] = float(get<uint16_t>(p + 12));
      b.classification[i] = extended ? p[16] : uint8_t(p[15] & 0x1F);
      if (L.hasColor) {
        const int sh = L.color8bit ? 0 : 8;
        b.r[i] = uint8_t(std::min<int>(255, get<uint16_t>(p + L.colorOffset) >> sh));
        b.g[i] = uint8_t(std::min<int>(255, get<uint16_t>(p + L.colorOffset + 2) >> sh));
        b.b[i] = uint8_t(std::min<int>(255, get<uint16_t>(p + L.colorOffset + 4) >> sh));
      }
    }
    done += n;
    SA_RETURN_IF_ERROR(sink.onPoints(b));
  }
  return Status::ok();
}

}  // namespace sa
