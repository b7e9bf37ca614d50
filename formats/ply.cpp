#include "formats/ply.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <sstream>

#include "common/fileio.h"

namespace sa {
namespace {

enum PlyType { kInvalid = 0, kI8, kU8, kI16, kU16, kI32, kU32, kF32, kF64 };

int typeFromName(const std::string& s) {
  if (s == "char" || s == "int8") return kI8;
  if (s == "uchar" || s == "uint8") return kU8;
  if (s == "short" || s == "int16") return kI16;
  if (s == "ushort" || s == "uint16") return kU16;
  if (s == "int" || s == "int32") return kI32;
  if (s == "uint" || s == "uint32") return kU32;
  if (s == "float" || s == "float32") return kF32;
  if (s == "double" || s == "float64") return kF64;
  return kInvalid;
}

size_t typeSize(int t) {
  switch (t) {
    case kI8: case kU8: return 1;
    case kI16: case kU16: return 2;
    case kI32: case kU32: case kF32: return 4;
    case kF64: return 8;
  }
  return 0;
}

std::vector<std::string> splitWords(const std::string& line) {
  std::vector<std::string> out;
  std::istringstream is(line);
  std::string w;
  while (is >> w) out.push_back(w);
  return out;
}

// Decodes one binary value of type t at p (bytes in file order) into a double.
inline double decodeBinary(const unsigned char* p, int t, bool swap) {
  unsigned char tmp[8];
  size_t n = typeSize(t);
  if (swap) {
    for (size_t i = 0; i < n; ++i) tmp[i] = p[n - 1 - i];
    p = tmp;
  }
  switch (t) {
    case kI8: { int8_t v; std::memcpy(&v, p, 1); return v; }
    case kU8: return p[0];
    case kI16: { int16_t v; std::memcpy(&v, p, 2); return v; }
    case kU16: { uint16_t v; std::memcpy(&v, p, 2); return v; }
    case kI32: { int32_t v; std::memcpy(&v, p, 4); return v; }
    case kU32: { uint32_t v; std::memcpy(&v, p, 4); return v; }
    case kF32: { float v; std::memcpy(&v, p, 4); return v; }
    case kF64: { double v; std::memcpy(&v, p, 8); return v; }
  }
  return 0;
}

// Role of a vertex property in our batch.
enum Role { kNone = -1, kX, kY, kZ, kNX, kNY, kNZ, kR, kG, kB, kIntensity, kConfidence, kClass, kRoleCount };

int roleOf(const std::string& n) {
  if (n == "x") return kX;
  if (n == "y") return kY;
  if (n == "z") return kZ;
  if (n == "nx") return kNX;
  if (n == "ny") return kNY;
  if (n == "nz") return kNZ;
  if (n == "red" || n == "r" || n == "diffuse_red") return kR;
  if (n == "green" || n == "g" || n == "diffuse_green") return kG;
  if (n == "blue" || n == "b" || n == "diffuse_blue") return kB;
  if (n == "intensity" || n == "scalar_intensity") return kIntensity;
  if (n == "confidence" || n == "scalar_confidence") return kConfidence;
  if (n == "classification" || n == "scalar_classification") return kClass;
  return kNone;
}

std::string formatCount(uint64_t v) { return std::to_string(v); }

class PlyParser {
 public:
  PlyParser(const PlyReadOptions& opt, BatchSink* sink) : opt_(opt), sink_(sink) {}

  Status parseHeader(const std::string& path) {
    SA_RETURN_IF_ERROR(in_.open(path));
    path_ = path;
    std::string line;
    if (!in_.readLine(line, 256) || line != "ply")
      return Status::badInput(path + ": not a PLY file (first line must be 'ply')");
    int lineNo = 1;
    bool haveFormat = false;
    while (true) {
      if (!in_.readLine(line, 1 << 16))
        return Status::badInput(path + ": header ends before 'end_header' (line " +
                                std::to_string(lineNo) + ")");
      ++lineNo;
      auto w = splitWords(line);
      if (w.empty()) continue;
      const std::string where = path + ":" + std::to_string(lineNo) + ": ";
      if (w[0] == "end_header") break;
      if (w[0] == "comment") continue;
      if (w[0] == "obj_info") {
        hdr_.objInfo.push_back(line.size() > 9 ? line.substr(9) : "");
        continue;
      }
      if (w[0] == "format") {
        if (w.size() < 3) return Status::badInput(where + "malformed format line");
        if (w[1] == "ascii") hdr_.format = PlyFormat::kAscii;
        else if (w[1] == "binary_little_endian") hdr_.format = PlyFormat::kBinaryLittle;
        else if (w[1] == "binary_big_endian") hdr_.format = PlyFormat::kBinaryBig;
        else return Status::badInput(where + "unknown format '" + w[1] + "'");
        if (w[2] != "1.0") return Status::badInput(where + "unsupported PLY version " + w[2]);
        haveFormat = true;
        continue;
      }
      if (w[0] == "element") {
        if (w.size() != 3) return Status::badInput(where + "expected 'element <name> <count>'");
        PlyElement e;
        e.name = w[1];
        auto [p, ec] = std::from_chars(w[2].data(), w[2].data() + w[2].size(), e.count);
        if (ec != std::errc() || p != w[2].data() + w[2].size())
          return Status::badInput(where + "element count '" + w[2] + "' is not a non-negative integer");
        hdr_.elements.push_back(std::move(e));
        continue;
      }
      if (w[0] == "property") {
        if (hdr_.elements.empty()) return Status::badInput(where + "property before any element");
        PlyProperty prop;
        if (w.size() == 5 && w[1] == "list") {
          prop.isList = true;
          prop.countType = typeFromName(w[2]);
          prop.type = typeFromName(w[3]);
          prop.name = w[4];
          if (!prop.countType || !prop.type) return Status::badInput(where + "unknown list type");
          if (prop.countType == kF32 || prop.countType == kF64)
            return Status::badInput(where + "list count type must be an integer type");
        } else if (w.size() == 3) {
          prop.type = typeFromName(w[1]);
          prop.name = w[2];
          if (!prop.type) return Status::badInput(where + "unknown property type '" + w[1] + "'");
        } else {
          return Status::badInput(where + "malformed property line");
        }
        hdr_.elements.back().properties.push_back(prop);
        continue;
      }
      // Not a PLY keyword (e.g. the 'bye' lines in Stanford's dragon scans): skip, as
      // Stanford's own ply library does, but tell the user.
      hdr_.warnings.push_back(path + ":" + std::to_string(lineNo) + ": skipped unknown header line '" +
                              line.substr(0, 60) + "'");
    }
    if (!haveFormat) return Status::badInput(path + ": header has no 'format' line");
    hdr_.headerBytes = in_.offset();
    line_ = static_cast<uint64_t>(lineNo);
    return validate();
  }

  // Rejects counts the file cannot hold, before anything is allocated for them.
  Status validate() {
    const bool ascii = hdr_.format == PlyFormat::kAscii;
    const uint64_t bodyBytes = in_.fileSize() - hdr_.headerBytes;
    long double minBytes = 0;
    for (const auto& e : hdr_.elements) {
      long double perRecord = 0;
      for (const auto& p : e.properties) {
        if (ascii) perRecord += 2;  // at least one digit and one separator
        else perRecord += p.isList ? typeSize(p.countType) : typeSize(p.type);
      }
      if (perRecord == 0 && e.count > 0 && !ascii)
        return Status::badInput(path_ + ": element '" + e.name + "' has no properties");
      minBytes += perRecord * static_cast<long double>(e.count);
      if (e.name == "vertex") {
        hdr_.vertexCount = e.count;
        bool n[3] = {}, c[3] = {}, pos[3] = {};
        for (const auto& p : e.properties) {
          int r = roleOf(p.name);
          if (r >= kX && r <= kZ && !p.isList) pos[r] = true;
          if (r >= kNX && r <= kNZ && !p.isList) n[r - kNX] = true;
          if (r >= kR && r <= kB && !p.isList) c[r - kR] = true;
          if (r == kIntensity && !p.isList) hdr_.hasIntensity = true;
          if (r == kConfidence && !p.isList) hdr_.hasConfidence = true;
          if (r == kClass && !p.isList) hdr_.hasClassification = true;
        }
        if (!(pos[0] && pos[1] && pos[2]))
          return Status::badInput(path_ + ": vertex element lacks x, y or z properties");
        hdr_.hasNormals = n[0] && n[1] && n[2];
        hdr_.hasColors = c[0] && c[1] && c[2];
      }
      if ((e.name == "face" || e.name == "tristrips") && e.count > 0) hdr_.hasFaces = true;
    }
    if (minBytes > static_cast<long double>(bodyBytes)) {
      std::string detail;
      for (const auto& e : hdr_.elements) {
        detail.append(" ").append(formatCount(e.count)).append(" ").append(e.name);
      }
      return Status::badInput(path_ + ": header declares" + detail + " but the body has only " +
                              std::to_string(bodyBytes) + " bytes (file truncated or header corrupt)");
    }
    return Status::ok();
  }

  Status parseBody() {
    for (const auto& e : hdr_.elements) {
      // Records without properties hold no bytes, however many the header declares (a fuzzed
      // header's 10^17 of them took a loop of that length to skip).
      if (e.properties.empty() && e.name != "vertex") continue;
      if (e.name == "vertex") {
        SA_RETURN_IF_ERROR(readVertices(e));
      } else if (opt_.readFaces && (e.name == "face" || e.name == "tristrips")) {
        SA_RETURN_IF_ERROR(readFaces(e, e.name == "tristrips"));
      } else if (opt_.rangeGridTriangles && e.name == "range_grid") {
        SA_RETURN_IF_ERROR(readRangeGrid(e));
      } else {
        SA_RETURN_IF_ERROR(skipElement(e));
      }
    }
    return Status::ok();
  }

  PlyHeader& header() { return hdr_; }

 private:
  bool binary() const { return hdr_.format != PlyFormat::kAscii; }
  bool swap() const {
    bool fileBig = hdr_.format == PlyFormat::kBinaryBig;
    return fileBig != (std::endian::native == std::endian::big);
  }

  Status truncated(const std::string& what) {
    return Status::badInput(path_ + ": unexpected end of file at byte " + std::to_string(in_.offset()) +
                            " while reading " + what);
  }

  // ---- ascii tokens ----
  // Reads the next whitespace-separated token; false at end of file.
  bool nextToken() {
    tok_.clear();
    int c = in_.get();
    while (c == ' ' || c == '\t' || c == '\n' || c == '\r') {
      if (c == '\n') ++line_;
      c = in_.get();
    }
    if (c < 0) return false;
    tokLine_ = line_ + 1;
    while (c >= 0 && c != ' ' && c != '\t' && c != '\n' && c != '\r') {
      if (tok_.size() < 64) tok_.push_back(static_cast<char>(c));
      c = in_.get();
    }
    if (c == '\n') ++line_;
    return true;
  }

  Status asciiValue(double& v, const std::string& what) {
    if (!nextToken()) return truncated(what);
    const char* b = tok_.data();
    const char* e = b + tok_.size();
    if (!tok_.empty() && *b == '+') ++b;
    auto [p, ec] = std::from_chars(b, e, v);
    if (ec != std::errc() || p != e) {
      if (tok_ == "nan" || tok_ == "NaN" || tok_ == "-nan") { v = NAN; return Status::ok(); }
      if (tok_ == "inf" || tok_ == "-inf") { v = tok_[0] == '-' ? -INFINITY : INFINITY; return Status::ok(); }
      return Status::badInput(path_ + ":" + std::to_string(tokLine_) + ": expected a number for " + what +
                              ", found '" + tok_ + "'");
    }
    return Status::ok();
  }

  Status readValue(int type, double& v, const std::string& what) {
    if (!binary()) return asciiValue(v, what);
    unsigned char b[8];
    if (!in_.read(b, typeSize(type))) return truncated(what);
    v = decodeBinary(b, type, swap());
    return Status::ok();
  }

  Status readListCount(const PlyProperty& p, uint64_t& n, const std::string& what) {
    double c;
    SA_RETURN_IF_ERROR(readValue(p.countType, c, what + " list count"));
    if (!(c >= 0) || c != std::floor(c) || c > 1e9)
      return Status::badInput(path_ + ": invalid list count " + std::to_string(c) + " in " + what +
                              " at byte " + std::to_string(in_.offset()));
    n = static_cast<uint64_t>(c);
    return Status::ok();
  }

  Status readVertices(const PlyElement& e) {
    std::vector<int> roles;
    bool fixed = true;
    size_t recordSize = 0;
    for (const auto& p : e.properties) {
      roles.push_back(p.isList ? kNone : roleOf(p.name));
      if (p.isList) fixed = false;
      recordSize += typeSize(p.type);
    }
    PointBatch batch;
    const bool wantN = hdr_.hasNormals, wantC = hdr_.hasColors;
    const bool wantI = hdr_.hasIntensity, wantK = hdr_.hasConfidence, wantL = hdr_.hasClassification;
    std::vector<unsigned char> raw;
    double vals[kRoleCount] = {};
    uint64_t done = 0;
    while (done < e.count) {
      size_t n = static_cast<size_t>(std::min<uint64_t>(opt_.batchPoints, e.count - done));
      batch.clear();
      batch.firstIndex = done;
      batch.x.resize(n); batch.y.resize(n); batch.z.resize(n);
      if (wantN) { batch.nx.resize(n); batch.ny.resize(n); batch.nz.resize(n); }
      if (wantC) { batch.r.resize(n); batch.g.resize(n); batch.b.resize(n); }
      if (wantI) batch.intensity.resize(n);
      if (wantK) batch.confidence.resize(n);
      if (wantL) batch.classification.resize(n);
      if (binary() && fixed) raw.resize(n * recordSize);
      if (binary() && fixed && !in_.read(raw.data(), raw.size()))
        return truncated("vertex " + std::to_string(done) + " of " + std::to_string(e.count));
      for (size_t i = 0; i < n; ++i) {
        size_t off = 0;
        for (size_t k = 0; k < e.properties.size(); ++k) {
          const auto& p = e.properties[k];
          double v = 0;
          if (binary() && fixed) {
            v = decodeBinary(raw.data() + i * recordSize + off, p.type, swap());
            off += typeSize(p.type);
          } else if (p.isList) {
            uint64_t cnt;
            SA_RETURN_IF_ERROR(readListCount(p, cnt, "vertex property " + p.name));
            for (uint64_t j = 0; j < cnt; ++j) SA_RETURN_IF_ERROR(readValue(p.type, v, "vertex list"));
            continue;
          } else {
            SA_RETURN_IF_ERROR(readValue(p.type, v, "vertex " + std::to_string(done + i) + " property " + p.name));
          }
          if (roles[k] != kNone) vals[roles[k]] = v;
        }
        batch.x[i] = vals[kX]; batch.y[i] = vals[kY]; batch.z[i] = vals[kZ];
        if (wantN) {
          batch.nx[i] = static_cast<float>(vals[kNX]);
          batch.ny[i] = static_cast<float>(vals[kNY]);
          batch.nz[i] = static_cast<float>(vals[kNZ]);
        }
        if (wantC) {
          batch.r[i] = static_cast<uint8_t>(std::clamp(vals[kR], 0.0, 255.0));
          batch.g[i] = static_cast<uint8_t>(std::clamp(vals[kG], 0.0, 255.0));
          batch.b[i] = static_cast<uint8_t>(std::clamp(vals[kB], 0.0, 255.0));
        }
        if (wantI) batch.intensity[i] = static_cast<float>(vals[kIntensity]);
        if (wantK) batch.confidence[i] = static_cast<float>(vals[kConfidence]);
        if (wantL) batch.classification[i] = static_cast<uint8_t>(std::clamp(vals[kClass], 0.0, 255.0));
      }
      done += n;
      if (sink_) SA_RETURN_IF_ERROR(sink_->onPoints(batch));
    }
    return Status::ok();
  }

  Status emitTriangles(std::vector<uint32_t>& tris, bool force) {
    if (tris.empty() || (!force && tris.size() < 3 * opt_.batchPoints)) return Status::ok();
    Status s = sink_ ? sink_->onTriangles(tris.data(), tris.size() / 3) : Status::ok();
    tris.clear();
    return s;
  }

  Status readFaces(const PlyElement& e, bool strips) {
    std::vector<uint32_t> tris;
    std::vector<int64_t> idx;
    const std::string what = strips ? "tristrips" : "face";
    for (uint64_t f = 0; f < e.count; ++f) {
      for (const auto& p : e.properties) {
        const bool isIndices = p.isList && (p.name == "vertex_indices" || p.name == "vertex_index");
        if (!p.isList) {
          double v;
          SA_RETURN_IF_ERROR(readValue(p.type, v, what + " property " + p.name));
          continue;
        }
        uint64_t cnt;
        SA_RETURN_IF_ERROR(readListCount(p, cnt, what + " " + std::to_string(f)));
        if (binary() && !isIndices) {
          if (!in_.skip(cnt * typeSize(p.type))) return truncated(what + " list");
          continue;
        }
        idx.clear();
        for (uint64_t j = 0; j < cnt; ++j) {
          double v;
          SA_RETURN_IF_ERROR(readValue(p.type, v, what + " " + std::to_string(f) + " index"));
          if (!isIndices) continue;
          if (v == -1 && strips) { idx.push_back(-1); continue; }
          if (!(v >= 0 && v < static_cast<double>(hdr_.vertexCount)))
            return Status::badInput(path_ + ": " + what + " " + std::to_string(f) + " refers to vertex " +
                                    std::to_string(static_cast<int64_t>(v)) + " but the file has " +
                                    std::to_string(hdr_.vertexCount) + " vertices");
          idx.push_back(static_cast<int64_t>(v));
        }
        if (!isIndices) continue;
        if (!strips) {
          for (size_t j = 2; j < idx.size(); ++j) {  // fan triangulation of a polygon
            tris.push_back(static_cast<uint32_t>(idx[0]));
            tris.push_back(static_cast<uint32_t>(idx[j - 1]));
            tris.push_back(static_cast<uint32_t>(idx[j]));
          }
        } else {
          // Triangle strips: -1 restarts; every other triangle flips winding; degenerate
          // triangles (repeated indices) are dropped.
          size_t start = 0;
          for (size_t j = 0; j <= idx.size(); ++j) {
            if (j == idx.size() || idx[j] < 0) {
              for (size_t k = start + 2; k < j; ++k) {
                int64_t a = idx[k - 2], b = idx[k - 1], c = idx[k];
                if (a == b || b == c || a == c) continue;
                if ((k - start) % 2) std::swap(a, b);
                tris.push_back(static_cast<uint32_t>(a));
                tris.push_back(static_cast<uint32_t>(b));
                tris.push_back(static_cast<uint32_t>(c));
              }
              start = j + 1;
            }
          }
        }
        SA_RETURN_IF_ERROR(emitTriangles(tris, false));
      }
    }
    return emitTriangles(tris, true);
  }

  // Grid entries are row-major with num_cols columns: each is an empty list (no sample) or
  // one vertex index.
  Status readRangeGrid(const PlyElement& e) {
    uint64_t cols = 0;
    for (const auto& info : hdr_.objInfo) {
      std::istringstream is(info);
      std::string key;
      uint64_t v;
      if (is >> key >> v && key == "num_cols") cols = v;
    }
    if (cols == 0 || cols > (1u << 20)) return Status::badInput(path_ + ": range_grid without a valid 'obj_info num_cols'");
    if (e.properties.size() != 1 || !e.properties[0].isList)
      return Status::badInput(path_ + ": range_grid must have one list property");
    std::vector<int64_t> prev(cols, -1), cur(cols, -1);
    std::vector<uint32_t> tris;
    for (uint64_t k = 0; k < e.count; ++k) {
      const uint64_t col = k % cols;
      if (col == 0 && k > 0) {
        std::swap(prev, cur);
        std::fill(cur.begin(), cur.end(), -1);
      }
      uint64_t cnt;
      SA_RETURN_IF_ERROR(readListCount(e.properties[0], cnt, "range_grid"));
      int64_t idx = -1;
      for (uint64_t j = 0; j < cnt; ++j) {
        double v;
        SA_RETURN_IF_ERROR(readValue(e.properties[0].type, v, "range_grid index"));
        if (j == 0) idx = static_cast<int64_t>(v);
      }
      if (idx >= static_cast<int64_t>(hdr_.vertexCount) || idx < -1)
        return Status::badInput(path_ + ": range_grid entry " + std::to_string(k) + " refers to vertex " +
                                std::to_string(idx) + " of " + std::to_string(hdr_.vertexCount));
      cur[col] = idx;
      if (k >= cols && col > 0) {
        const int64_t a = prev[col - 1], b = prev[col], c = cur[col - 1], d = cur[col];
        auto tri = [&](int64_t x, int64_t y, int64_t z) {
          if (x < 0 || y < 0 || z < 0) return;
          tris.insert(tris.end(), {uint32_t(x), uint32_t(y), uint32_t(z)});
        };
        if (a >= 0 && b >= 0 && c >= 0 && d >= 0) {
          tri(a, c, b);
          tri(b, c, d);
        } else {  // three of the four: one triangle
          if (d < 0) tri(a, c, b);
          if (a < 0) tri(b, c, d);
          if (b < 0) tri(a, c, d);
          if (c < 0) tri(a, d, b);
        }
      }
      SA_RETURN_IF_ERROR(emitTriangles(tris, false));
    }
    return emitTriangles(tris, true);
  }

  Status skipElement(const PlyElement& e) {
    bool fixed = true;
    uint64_t recordSize = 0;
    for (const auto& p : e.properties) {
      if (p.isList) fixed = false;
      recordSize += typeSize(p.type);
    }
    if (binary() && fixed) {
      if (!in_.skip(recordSize * e.count)) return truncated("element '" + e.name + "'");
      return Status::ok();
    }
    for (uint64_t i = 0; i < e.count; ++i) {
      for (const auto& p : e.properties) {
        if (!p.isList) {
          if (binary()) {
            if (!in_.skip(typeSize(p.type))) return truncated("element '" + e.name + "'");
          } else if (!nextToken()) {
            return truncated("element '" + e.name + "'");
          }
          continue;
        }
        uint64_t cnt;
        SA_RETURN_IF_ERROR(readListCount(p, cnt, "element '" + e.name + "'"));
        if (binary()) {
          if (!in_.skip(cnt * typeSize(p.type))) return truncated("element '" + e.name + "'");
        } else {
          for (uint64_t j = 0; j < cnt; ++j)
            if (!nextToken()) return truncated("element '" + e.name + "'");
        }
      }
    }
    return Status::ok();
  }

  PlyReadOptions opt_;
  BatchSink* sink_;
  BufferedReader in_;
  std::string path_;
  PlyHeader hdr_;
  std::string tok_;
  uint64_t line_ = 0, tokLine_ = 0;
};

}  // namespace

Result<PlyHeader> readPlyHeader(const std::string& path) {
  PlyParser p(PlyReadOptions{}, nullptr);
  Status s = p.parseHeader(path);
  if (!s) return s;
  return p.header();
}

Status readPly(const std::string& path, const PlyReadOptions& options, BatchSink& sink, PlyHeader* header) {
  PlyParser p(options, &sink);
  SA_RETURN_IF_ERROR(p.parseHeader(path));
  if (header) *header = p.header();
  return p.parseBody();
}

}  // namespace sa
