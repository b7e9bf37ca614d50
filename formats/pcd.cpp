// The only file that includes PCL (its headers are heavy and pull in VTK and Boost).
#include "formats/pcd.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include <pcl/PCLPointCloud2.h>
#include <pcl/console/print.h>
#include <pcl/io/lzf.h>
#include <pcl/io/pcd_io.h>

#include "common/fileio.h"

namespace sa {
namespace {

constexpr uint64_t kMaxPoints = 0xFFFFFFFFull;  // PCL indexes points with 32-bit unsigned integers
constexpr size_t kMaxFields = 4096;
constexpr uint32_t kMaxCount = 1u << 20;
constexpr uint32_t kMaxPointStep = 1u << 24;
// LZF's longest back reference (264 bytes) costs 3 bytes: no valid block expands more than this.
constexpr uint64_t kMaxLzfRatio = 89;

std::vector<std::string> words(const std::string& line) {
  std::vector<std::string> out;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    const size_t b = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
    if (i > b) out.push_back(line.substr(b, i - b));
  }
  return out;
}

bool parseU64(const std::string& s, uint64_t& v) {
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  return ec == std::errc() && p == s.data() + s.size();
}

bool isNanToken(const std::string& t) {
  if (t.size() != 3) return false;
  return std::tolower(t[0]) == 'n' && std::tolower(t[1]) == 'a' && std::tolower(t[2]) == 'n';
}

bool numberToken(const std::string& t) {
  double v;
  const char* b = t.data();
  const char* e = b + t.size();
  if (b != e && *b == '+') ++b;
  auto [p, ec] = std::from_chars(b, e, v);
  return (ec == std::errc() || ec == std::errc::result_out_of_range) && p == e && b != e;
}

uint8_t pclType(const PcdField& f) {
  using PF = pcl::PCLPointField;
  if (f.type == 'F') return f.size == 8 ? PF::FLOAT64 : PF::FLOAT32;
  if (f.type == 'I') return f.size == 1 ? PF::INT8 : f.size == 2 ? PF::INT16 : f.size == 4 ? PF::INT32 : PF::INT64;
  return f.size == 1 ? PF::UINT8 : f.size == 2 ? PF::UINT16 : f.size == 4 ? PF::UINT32 : PF::UINT64;
}

double fieldValue(const uint8_t* p, const PcdField& f) {
  auto get = [p](auto v) {
    std::memcpy(&v, p, sizeof(v));
    return double(v);
  };
  if (f.type == 'F') return f.size == 8 ? get(double()) : get(float());
  if (f.type == 'I') {
    switch (f.size) {
      case 1: return get(int8_t());
      case 2: return get(int16_t());
      case 4: return get(int32_t());
      default: return get(int64_t());
    }
  }
  switch (f.size) {
    case 1: return get(uint8_t());
    case 2: return get(uint16_t());
    case 4: return get(uint32_t());
    default: return get(uint64_t());
  }
}

struct Roles {
  int x = -1, y = -1, z = -1, nx = -1, ny = -1, nz = -1, rgb = -1, intensity = -1;
};

Roles rolesOf(const std::vector<PcdField>& fields) {
  Roles r;
  for (size_t i = 0; i < fields.size(); ++i) {
    const std::string& n = fields[i].name;
    const int k = static_cast<int>(i);
    if (fields[i].count != 1) continue;
    if (n == "x") r.x = k;
    else if (n == "y") r.y = k;
    else if (n == "z") r.z = k;
    else if (n == "normal_x") r.nx = k;
    else if (n == "normal_y") r.ny = k;
    else if (n == "normal_z") r.nz = k;
    else if ((n == "rgb" || n == "rgba") && fields[i].size == 4) r.rgb = k;
    else if (n == "intensity") r.intensity = k;
  }
  return r;
}

// Converts `n` packed point records (PCL's PCLPointCloud2::data layout) into a batch,
// skipping entries without finite coordinates.
class RecordConverter {
 public:
  RecordConverter(const PcdHeader& h, BatchSink& sink) : h_(h), r_(rolesOf(h.fields)), sink_(sink) {}
  Status convert(const uint8_t* data, size_t n, uint64_t firstIndex, uint32_t step) {
    batch_.clear();
    batch_.firstIndex = firstIndex;
    const auto& F = h_.fields;
    for (size_t i = 0; i < n; ++i) {
      const uint8_t* p = data + i * step;
      const double x = fieldValue(p + F[r_.x].offset, F[r_.x]);
      const double y = fieldValue(p + F[r_.y].offset, F[r_.y]);
      const double z = fieldValue(p + F[r_.z].offset, F[r_.z]);
      if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
        ++holes_;
        continue;
      }
      batch_.x.push_back(x);
      batch_.y.push_back(y);
      batch_.z.push_back(z);
      if (h_.hasNormals) {
        batch_.nx.push_back(float(fieldValue(p + F[r_.nx].offset, F[r_.nx])));
        batch_.ny.push_back(float(fieldValue(p + F[r_.ny].offset, F[r_.ny])));
        batch_.nz.push_back(float(fieldValue(p + F[r_.nz].offset, F[r_.nz])));
      }
      if (h_.hasColors) {
        uint32_t c;
        std::memcpy(&c, p + F[r_.rgb].offset, 4);  // PCL packs 0x(AA)RRGGBB in either a float or a uint32
        batch_.r.push_back(uint8_t(c >> 16));
        batch_.g.push_back(uint8_t(c >> 8));
        batch_.b.push_back(uint8_t(c));
      }
      if (h_.hasIntensity) batch_.intensity.push_back(float(fieldValue(p + F[r_.intensity].offset, F[r_.intensity])));
    }
    if (batch_.size() == 0) return Status::ok();
    return sink_.onPoints(batch_);
  }
  uint64_t holes() const { return holes_; }

 private:
  const PcdHeader& h_;
  Roles r_;
  BatchSink& sink_;
  PointBatch batch_;
  uint64_t holes_ = 0;
};

pcl::PCLPointCloud2 emptyCloud(const PcdHeader& h) {
  pcl::PCLPointCloud2 c;
  for (const auto& f : h.fields) {
    pcl::PCLPointField pf;
    pf.name = f.name;
    pf.offset = f.offset;
    pf.datatype = pclType(f);
    pf.count = f.count;
    c.fields.push_back(pf);
  }
  c.point_step = h.pointStep;
  c.height = 1;
  c.is_bigendian = false;
  return c;
}

void quietPcl() { pcl::console::setVerbosityLevel(pcl::console::L_ALWAYS); }

// A read-only mapping of a whole file.
class Mapping {
 public:
  ~Mapping() {
    if (map_ != MAP_FAILED) ::munmap(map_, size_);
    if (fd_ >= 0) ::close(fd_);
  }
  Status open(const std::string& path, uint64_t size) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) return Status::badInput(path + ": cannot open (" + std::strerror(errno) + ")");
    size_ = size;
    map_ = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd_, 0);
    if (map_ == MAP_FAILED) return Status::internal(path + ": cannot map the file (" + std::strerror(errno) + ")");
    ::madvise(map_, size_, MADV_SEQUENTIAL);
    return Status::ok();
  }
  const uint8_t* data() const { return static_cast<const uint8_t*>(map_); }
  // Drops the pages below `end` from this process's memory (they are file-backed).
  void release(uint64_t end) {
    const uint64_t page = uint64_t(sysconf(_SC_PAGESIZE));
    const uint64_t cut = end / page * page;
    if (cut > released_) {
      ::madvise(static_cast<char*>(map_) + released_, cut - released_, MADV_DONTNEED);
      released_ = cut;
    }
  }

 private:
  int fd_ = -1;
  void* map_ = MAP_FAILED;
  uint64_t size_ = 0, released_ = 0;
};

}  // namespace

namespace {

// The header's keyword lines as they are read (what has been seen decides the defaults).
struct HeaderLines {
  PcdHeader h;
  bool data = false, width = false, height = false, points = false, size = false, type = false;
};

// One SIZE, TYPE or COUNT entry into field f, or what is wrong with it.
std::string fieldEntry(const std::string& key, const std::string& t, PcdField& f) {
  uint64_t v = 0;
  if (key == "SIZE") {
    if (!parseU64(t, v) || (v != 1 && v != 2 && v != 4 && v != 8))
      return "SIZE of field '" + f.name + "' is '" + t + "' (expected 1, 2, 4 or 8)";
    f.size = int(v);
  } else if (key == "TYPE") {
    if (t.size() != 1 || (t[0] != 'I' && t[0] != 'U' && t[0] != 'F')) return "TYPE of field '" + f.name + "' is '" + t + "' (expected I, U or F)";
    f.type = t[0];
  } else {
    if (!parseU64(t, v) || v < 1 || v > kMaxCount)
      return "COUNT of field '" + f.name + "' is '" + t + "' (expected 1 to " + std::to_string(kMaxCount) + ")";
    f.count = uint32_t(v);
  }
  return {};
}

// headerLine's answer for a keyword this format does not have.
const std::string kUnknownKeyword = "?";

// One header line's words (w[0] the keyword) into `hl`: "" when understood, else what is wrong
// (kUnknownKeyword for a keyword this format does not have).
std::string headerLine(const std::vector<std::string>& w, HeaderLines& hl) {
  PcdHeader& h = hl.h;
  const std::string& key = w[0];
  const size_t n = w.size() - 1;
  if (key == "VERSION") return {};
  if (key == "FIELDS" || key == "COLUMNS") {
    if (n == 0 || n > kMaxFields) return "FIELDS must name 1 to " + std::to_string(kMaxFields) + " fields";
    h.fields.clear();
    for (size_t i = 1; i < w.size(); ++i) h.fields.push_back(PcdField{w[i], 4, 'F', 1, 0});
    return {};
  }
  if (key == "SIZE" || key == "TYPE" || key == "COUNT") {
    if (h.fields.empty()) return key + " before FIELDS";
    if (n != h.fields.size()) return key + " has " + std::to_string(n) + " entries but FIELDS names " + std::to_string(h.fields.size());
    for (size_t i = 0; i < n; ++i)
      if (std::string e = fieldEntry(key, w[i + 1], h.fields[i]); !e.empty()) return e;
    hl.size |= key == "SIZE";
    hl.type |= key == "TYPE";
    return {};
  }
  if (key == "WIDTH" || key == "HEIGHT" || key == "POINTS") {
    uint64_t v = 0;
    if (n != 1 || !parseU64(w[1], v)) return key + " must be one non-negative integer";
    if (key == "WIDTH") h.width = v, hl.width = true;
    else if (key == "HEIGHT") h.height = v, hl.height = true;
    else h.points = v, hl.points = true;
    return {};
  }
  if (key == "VIEWPOINT") return n == 7 ? std::string() : "VIEWPOINT needs 7 numbers (tx ty tz qw qx qy qz)";
  if (key == "DATA") {
    if (n != 1) return "DATA needs one word (ascii, binary or binary_compressed)";
    if (w[1] == "ascii") h.encoding = PcdEncoding::kAscii;
    else if (w[1] == "binary") h.encoding = PcdEncoding::kBinary;
    else if (w[1] == "binary_compressed") h.encoding = PcdEncoding::kBinaryCompressed;
    else return "unknown DATA encoding '" + w[1] + "' (ascii, binary or binary_compressed)";
    hl.data = true;
    return {};
  }
  return kUnknownKeyword;
}

// The header's lines up to and including DATA.
Status readHeaderLines(const std::string& path, BufferedReader& in, HeaderLines& hl, int& lineNo) {
  std::string line;
  while (!hl.data) {
    if (in.offset() > (1 << 20)) return Status::badInput(path + ": no DATA line in the first MiB (not a PCD file?)");
    if (!in.readLine(line, 1 << 16)) {
      if (lineNo == 0) return Status::badInput(path + ": empty file");
      return Status::badInput(path + ": the header ends before its DATA line (line " + std::to_string(lineNo) + ")");
    }
    ++lineNo;
    const auto w = words(line);
    if (w.empty() || w[0][0] == '#') continue;
    const std::string e = headerLine(w, hl);
    if (e.empty()) continue;
    if (e == kUnknownKeyword && lineNo == 1)
      return Status::badInput(path + ": not a PCD file (line 1 is neither a comment nor a PCD header keyword)");
    return Status::badInput(path + ": line " + std::to_string(lineNo) + ": " +
                            (e == kUnknownKeyword ? "unknown header keyword '" + w[0].substr(0, 40) + "'" : e));
  }
  return Status::ok();
}

// The fields' offsets, the point step and the point counts the header's lines imply.
Status completeLayout(const std::string& path, HeaderLines& hl) {
  PcdHeader& h = hl.h;
  if (h.fields.empty()) return Status::badInput(path + ": the header has no FIELDS line");
  if (!hl.size || !hl.type) return Status::badInput(path + ": the header lacks a SIZE or TYPE line");
  for (const auto& f : h.fields)
    if (f.type == 'F' && f.size != 4 && f.size != 8)
      return Status::badInput(path + ": field '" + f.name + "' is a " + std::to_string(f.size) + "-byte float");
  uint64_t step = 0;
  for (auto& f : h.fields) {
    f.offset = uint32_t(step);
    step += uint64_t(f.size) * f.count;
    if (step > kMaxPointStep) return Status::badInput(path + ": a point record would exceed " + std::to_string(kMaxPointStep) + " bytes");
  }
  h.pointStep = uint32_t(step);
  if (!hl.points && !hl.width) return Status::badInput(path + ": the header gives neither POINTS nor WIDTH");
  if (!hl.points) h.points = h.width * (hl.height ? h.height : 1);
  if (!hl.width && !hl.height) h.width = h.points, h.height = 1;
  if (!hl.height) h.height = 1;
  if (h.points > kMaxPoints)
    return Status::badInput(path + ": POINTS " + std::to_string(h.points) + " is more than PCL's reader can index (" +
                            std::to_string(kMaxPoints) + ")");
  if (h.width > kMaxPoints || h.height > kMaxPoints || h.width * h.height != h.points)
    return Status::badInput(path + ": WIDTH " + std::to_string(h.width) + " x HEIGHT " + std::to_string(h.height) +
                            " is not POINTS " + std::to_string(h.points));
  const Roles r = rolesOf(h.fields);
  if (r.x < 0 || r.y < 0 || r.z < 0) return Status::badInput(path + ": the fields must include x, y and z (one element each)");
  h.hasNormals = r.nx >= 0 && r.ny >= 0 && r.nz >= 0;
  h.hasColors = r.rgb >= 0;
  h.hasIntensity = r.intensity >= 0;
  return Status::ok();
}

// The binary_compressed body's 8-byte size prefix against the file and the header.
Status checkCompressedPrefix(const std::string& path, BufferedReader& in, const PcdHeader& h, uint64_t body, long double need) {
  uint32_t sizes[2] = {0, 0};
  if (body < 8 || !in.read(sizes, 8))
    return Status::badInput(path + ": binary_compressed body shorter than its 8-byte size prefix (byte " + std::to_string(h.dataOffset) + ")");
  const uint64_t compressed = sizes[0], uncompressed = sizes[1];
  if (compressed > body - 8)
    return Status::badInput(path + ": compressed block of " + std::to_string(compressed) + " bytes at byte " +
                            std::to_string(h.dataOffset + 8) + " runs past the end of the file (" + std::to_string(in.fileSize()) + " bytes)");
  if (static_cast<long double>(uncompressed) != need)
    return Status::badInput(path + ": compressed block decompresses to " + std::to_string(uncompressed) + " bytes but " +
                            std::to_string(h.points) + " points of " + std::to_string(h.pointStep) + " bytes need " +
                            std::to_string(uint64_t(need)) + " (header corrupt)");
  if (uncompressed > compressed * kMaxLzfRatio)
    return Status::badInput(path + ": a " + std::to_string(compressed) + "-byte LZF block cannot hold " + std::to_string(uncompressed) +
                            " bytes (header corrupt)");
  return Status::ok();
}

// The sizes the body must have, checked before anything is allocated.
Status checkBodySize(const std::string& path, BufferedReader& in, const PcdHeader& h) {
  const uint64_t body = in.fileSize() - h.dataOffset;
  const long double need = static_cast<long double>(h.points) * h.pointStep;
  if (h.encoding == PcdEncoding::kBinary) {
    if (need > static_cast<long double>(body))
      return Status::badInput(path + ": header declares " + std::to_string(h.points) + " points of " + std::to_string(h.pointStep) +
                              " bytes but the body has only " + std::to_string(body) + " bytes (file truncated or header corrupt)");
    return Status::ok();
  }
  if (h.encoding == PcdEncoding::kAscii) {
    uint64_t elems = 0;
    for (const auto& f : h.fields) elems += f.count;
    if (static_cast<long double>(h.points) * elems * 2 > static_cast<long double>(body) + 1)
      return Status::badInput(path + ": header declares " + std::to_string(h.points) + " points but the ascii body has only " +
                              std::to_string(body) + " bytes (file truncated or header corrupt)");
    return Status::ok();
  }
  return checkCompressedPrefix(path, in, h, body, need);
}

}  // namespace

Result<PcdHeader> readPcdHeader(const std::string& path) {
  BufferedReader in;
  SA_RETURN_IF_ERROR(in.open(path, 1 << 16));
  HeaderLines hl;
  int lineNo = 0;
  SA_RETURN_IF_ERROR(readHeaderLines(path, in, hl, lineNo));
  hl.h.dataOffset = in.offset();
  hl.h.headerLines = uint64_t(lineNo);
  SA_RETURN_IF_ERROR(completeLayout(path, hl));
  SA_RETURN_IF_ERROR(checkBodySize(path, in, hl.h));
  return hl.h;
}

namespace {

// binary_compressed: one LZF block holding each field's values for all points, field after
// field. PCL's decompressor inflates it; the header PCL never parses (its parser reads some
// headers differently from this one and crashed on a fuzzed file that passed the checks above).
Status readCompressedBody(const std::string& path, const PcdHeader& h, uint64_t fileBytes, size_t batchPoints, RecordConverter& conv) {
  Mapping map;
  SA_RETURN_IF_ERROR(map.open(path, fileBytes));
  uint32_t sizes[2];
  std::memcpy(sizes, map.data() + h.dataOffset, 8);
  const uint64_t total = uint64_t(h.points) * h.pointStep;  // equals sizes[1], checked with the header
  std::vector<uint8_t> soa(total);
  if (total > 0 && pcl::lzfDecompress(map.data() + h.dataOffset + 8, sizes[0], soa.data(), static_cast<unsigned int>(total)) != total)
    return Status::badInput(path + ": the binary_compressed block at byte " + std::to_string(h.dataOffset + 8) +
                            " does not decompress to " + std::to_string(total) + " bytes (LZF data corrupt)");
  std::vector<uint64_t> fieldStart;
  uint64_t at = 0;
  for (const auto& f : h.fields) {
    fieldStart.push_back(at);
    at += uint64_t(f.size) * f.count * h.points;
  }
  std::vector<uint8_t> aos;
  for (uint64_t done = 0; done < h.points; done += batchPoints) {
    const size_t n = size_t(std::min<uint64_t>(batchPoints, h.points - done));
    aos.resize(n * h.pointStep);
    for (size_t k = 0; k < h.fields.size(); ++k) {
      const size_t bytes = size_t(h.fields[k].size) * h.fields[k].count;
      const uint8_t* src = soa.data() + fieldStart[k] + done * bytes;
      for (size_t i = 0; i < n; ++i) std::memcpy(aos.data() + i * h.pointStep + h.fields[k].offset, src + i * bytes, bytes);
    }
    SA_RETURN_IF_ERROR(conv.convert(aos.data(), n, done, h.pointStep));
  }
  return Status::ok();
}

Status readBinaryBody(const std::string& path, const PcdHeader& h, uint64_t fileBytes, size_t batchPoints, RecordConverter& conv) {
  Mapping map;
  SA_RETURN_IF_ERROR(map.open(path, fileBytes));
  pcl::PCDReader reader;
  pcl::PCLPointCloud2 cloud = emptyCloud(h);
  for (uint64_t done = 0; done < h.points; done += batchPoints) {
    const size_t n = size_t(std::min<uint64_t>(batchPoints, h.points - done));
    cloud.width = uint32_t(n);
    cloud.row_step = uint32_t(n * h.pointStep);
    cloud.data.resize(n * h.pointStep);
    const uint64_t at = h.dataOffset + done * h.pointStep;
    if (reader.readBodyBinary(map.data() + at, cloud, pcl::PCDReader::PCD_V7, false, 0) < 0)
      return Status::badInput(path + ": PCL could not read the binary body at byte " + std::to_string(at));
    SA_RETURN_IF_ERROR(conv.convert(cloud.data.data(), n, done, h.pointStep));
    map.release(at + n * h.pointStep);
  }
  return Status::ok();
}

// Up to `want` point lines of an ascii body into `text`, each checked (count and number syntax,
// by line and column, since PCL reads a malformed number as 0); `got` counts them.
Status takeAsciiLines(const std::string& path, std::istream& fs, uint64_t elems, size_t want, uint64_t& lineNo, std::string& text,
                      size_t& got) {
  std::string line;
  text.clear();
  got = 0;
  while (got < want && std::getline(fs, line)) {
    ++lineNo;
    const auto w = words(line);
    if (w.empty()) continue;
    if (w.size() != elems)
      return Status::badInput(path + ":" + std::to_string(lineNo) + ": expected " + std::to_string(elems) + " values, found " +
                              std::to_string(w.size()));
    for (size_t c = 0; c < w.size(); ++c)
      if (!numberToken(w[c]) && !isNanToken(w[c]))
        return Status::badInput(path + ":" + std::to_string(lineNo) + ": column " + std::to_string(c + 1) + ": expected a number, found '" +
                                w[c].substr(0, 40) + "'");
    text.append(line).push_back('\n');
    ++got;
  }
  return Status::ok();
}

// ascii: lines checked here, then parsed by PCL one batch at a time.
Status readAsciiBody(const std::string& path, const PcdHeader& h, size_t batchPoints, RecordConverter& conv) {
  std::ifstream fs(path, std::ios::binary);
  if (!fs) return Status::badInput(path + ": cannot open");
  fs.seekg(std::streamoff(h.dataOffset));
  uint64_t elems = 0;
  for (const auto& f : h.fields) elems += f.count;
  uint64_t lineNo = h.headerLines;
  pcl::PCDReader reader;
  pcl::PCLPointCloud2 cloud = emptyCloud(h);
  std::string text;
  for (uint64_t done = 0; done < h.points;) {
    const size_t want = size_t(std::min<uint64_t>(batchPoints, h.points - done));
    size_t got = 0;
    SA_RETURN_IF_ERROR(takeAsciiLines(path, fs, elems, want, lineNo, text, got));
    if (got < want)
      return Status::badInput(path + ": the file ends after " + std::to_string(done + got) + " of " + std::to_string(h.points) +
                              " points (line " + std::to_string(lineNo) + ")");
    cloud.width = uint32_t(got);
    cloud.row_step = uint32_t(got * h.pointStep);
    cloud.data.assign(got * h.pointStep, 0);
    std::istringstream is(text);
    if (reader.readBodyASCII(is, cloud, pcl::PCDReader::PCD_V7) < 0)
      return Status::badInput(path + ": PCL could not parse the points before line " + std::to_string(lineNo));
    SA_RETURN_IF_ERROR(conv.convert(cloud.data.data(), got, done, h.pointStep));
    done += got;
  }
  return Status::ok();
}

}  // namespace

Status readPcd(const std::string& path, size_t batchPoints, BatchSink& sink, uint64_t* holes) {
  auto hdr = readPcdHeader(path);
  if (!hdr) return hdr.status();
  const PcdHeader& h = *hdr;
  quietPcl();
  RecordConverter conv(h, sink);
  batchPoints = std::max<size_t>(1, batchPoints);
  auto fileBytes = fileSize(path);
  if (!fileBytes) return fileBytes.status();
  if (h.encoding == PcdEncoding::kBinaryCompressed) {
    SA_RETURN_IF_ERROR(readCompressedBody(path, h, *fileBytes, batchPoints, conv));
  } else if (h.encoding == PcdEncoding::kBinary) {
    SA_RETURN_IF_ERROR(readBinaryBody(path, h, *fileBytes, batchPoints, conv));
  } else {
    SA_RETURN_IF_ERROR(readAsciiBody(path, h, batchPoints, conv));
  }
  if (holes) *holes = conv.holes();
  return Status::ok();
}

}  // namespace sa
