#include "preprocess/chunker.h"

#include <xxhash.h>
#include <zstd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <algorithm>
#include <atomic>
#include <map>

#include <Eigen/Geometry>

#include "common/fileio.h"

namespace sa {
namespace {

// ---- chunk files: frames of compressed records ----
// A chunk file is a sequence of frames: u32 record count (1..kMaxFrameRecords), u32 compressed
// bytes, then the records byte-shuffled (byte b of every record together: positions, normals and
// ids compress far better as planes) and zstd-compressed at level 1. Packing writes and rereads
// every point two or three times; raw 36-byte records made the temporary files twice the input.
constexpr uint32_t kMaxFrameRecords = 1u << 16;
std::atomic<uint64_t> gScratchBytes{0}, gScratchRaw{0};

// One compression and one decompression context per thread, freed with it.
struct Zstd {
  ZSTD_CCtx* c = ZSTD_createCCtx();
  ZSTD_DCtx* d = ZSTD_createDCtx();
  ~Zstd() {
    ZSTD_freeCCtx(c);
    ZSTD_freeDCtx(d);
  }
};
Zstd& zstd() {
  thread_local Zstd z;
  return z;
}

// Byte b of record i to planes[b * m + i] (shuffle) and back (unshuffle), 16 records at a time:
// each plane then gets 16 consecutive bytes instead of one (a byte at a time, the shuffle was
// 5 % of packing a LAS).
constexpr size_t kRec = sizeof(ChunkPoint);
void shuffleRecords(const uint8_t* src, size_t m, uint8_t* planes) {
  size_t i = 0;
  for (; i + 16 <= m; i += 16) {
    uint8_t block[16 * kRec];
    std::memcpy(block, src + i * kRec, sizeof(block));
    for (size_t b = 0; b < kRec; ++b) {
      uint8_t row[16];
      for (size_t k = 0; k < 16; ++k) row[k] = block[k * kRec + b];
      std::memcpy(planes + b * m + i, row, 16);
    }
  }
  for (; i < m; ++i)
    for (size_t b = 0; b < kRec; ++b) planes[b * m + i] = src[i * kRec + b];
}
void unshuffleRecords(const uint8_t* planes, size_t m, uint8_t* dst) {
  size_t i = 0;
  for (; i + 16 <= m; i += 16) {
    uint8_t block[16 * kRec];
    for (size_t b = 0; b < kRec; ++b) {
      uint8_t row[16];
      std::memcpy(row, planes + b * m + i, 16);
      for (size_t k = 0; k < 16; ++k) block[k * kRec + b] = row[k];
    }
    std::memcpy(dst + i * kRec, block, sizeof(block));
  }
  for (; i < m; ++i)
    for (size_t b = 0; b < kRec; ++b) dst[i * kRec + b] = planes[b * m + i];
}

Status writeFrames(std::FILE* f, const std::string& path, const ChunkPoint* pts, size_t n) {
  ZSTD_CCtx* cctx = zstd().c;
  thread_local std::vector<uint8_t> planes, packed;
  for (size_t at = 0; at < n; at += kMaxFrameRecords) {
    const size_t m = std::min<size_t>(kMaxFrameRecords, n - at);
    planes.resize(m * kRec);
    shuffleRecords(reinterpret_cast<const uint8_t*>(pts + at), m, planes.data());
    packed.resize(ZSTD_compressBound(planes.size()));
    const size_t c = ZSTD_compressCCtx(cctx, packed.data(), packed.size(), planes.data(), planes.size(), 1);
    if (ZSTD_isError(c)) return Status::internal(path + ": cannot compress a chunk frame: " + ZSTD_getErrorName(c));
    const uint32_t head[2] = {uint32_t(m), uint32_t(c)};
    if (std::fwrite(head, 4, 2, f) != 2 || std::fwrite(packed.data(), 1, c, f) != c)
      return Status::internal(path + ": short write (disk full?)");
    gScratchBytes += 8 + c;
    gScratchRaw += m * kRec;
  }
  return Status::ok();
}

// Reads the next frame into out (replacing it); false at the end of the file. A frame that does
// not decode (a truncated or foreign file) is an error naming the file.
Result<bool> readFrame(std::FILE* f, const std::string& path, std::vector<ChunkPoint>& out) {
  ZSTD_DCtx* dctx = zstd().d;
  thread_local std::vector<uint8_t> planes, packed;
  uint32_t head[2];
  const size_t got = std::fread(head, 4, 2, f);
  if (got == 0 && std::feof(f)) return false;
  if (got != 2 || head[0] == 0 || head[0] > kMaxFrameRecords || head[1] > ZSTD_compressBound(size_t(head[0]) * kRec))
    return Status::internal(path + ": chunk file is damaged (a frame header out of range)");
  packed.resize(head[1]);
  if (std::fread(packed.data(), 1, head[1], f) != head[1]) return Status::internal(path + ": chunk file is truncated");
  planes.resize(size_t(head[0]) * kRec);
  const size_t d = ZSTD_decompressDCtx(dctx, planes.data(), planes.size(), packed.data(), packed.size());
  if (ZSTD_isError(d) || d != planes.size()) return Status::internal(path + ": chunk file is damaged (a frame does not decode)");
  const size_t m = head[0];
  out.resize(m);
  unshuffleRecords(planes.data(), m, reinterpret_cast<uint8_t*>(out.data()));
  return true;
}

bool finite3(double x, double y, double z) { return std::isfinite(x) && std::isfinite(y) && std::isfinite(z); }

class BoundsSink : public BatchSink {
 public:
  BoundsSink(BoundsInfo& out, const ProgressFn& p, uint64_t total, const InputSet& in, bool strict, bool hash)
      : out_(out), progress_(p), total_(total), in_(in), strict_(strict) {
    if (hash) {
      hash_ = XXH3_createState();
      XXH3_64bits_reset(hash_);
    }
  }
  ~BoundsSink() override {
    if (hash_) XXH3_freeState(hash_);
  }
  BoundsSink(const BoundsSink&) = delete;
  BoundsSink& operator=(const BoundsSink&) = delete;
  uint64_t digest() const { return hash_ ? XXH3_64bits_digest(hash_) : 0; }
  Status onPoints(const PointBatch& b) override {
    if (hash_) hashBatch(b);
    for (size_t i = 0; i < b.size(); ++i) {
      if (!finite3(b.x[i], b.y[i], b.z[i])) {
        if (strict_) {
          const auto [file, index] = in_.locate(b.firstIndex + i);
          return Status::badInput(file + ": vertex " + std::to_string(index) +
                                  " has a NaN or infinite coordinate (--strict; without it such points are skipped)");
        }
        ++out_.skipped;
        continue;
      }
      Eigen::Vector3d p(b.x[i], b.y[i], b.z[i]);
      if (b.hasColors() && !out_.colorVaries) {
        const uint8_t c[3] = {b.r[i], b.g[i], b.b[i]};
        if (!haveColor_) std::copy(c, c + 3, first_), haveColor_ = true;
        out_.colorVaries = !std::equal(c, c + 3, first_);
      }
      out_.min = out_.min.cwiseMin(p);
      out_.max = out_.max.cwiseMax(p);
      const Eigen::Vector3d d = p - (out_.count == 0 ? (ref_ = p) : ref_);  // shifted sums: no cancellation
      sum_ += d;
      scatter_ += d * d.transpose();
      ++out_.count;
    }
    seen_ += b.size();
    if (progress_) progress_("count", seen_, total_);
    return Status::ok();
  }
  Eigen::Vector3d centroid() const { return out_.count ? ref_ + sum_ / double(out_.count) : ref_; }
  Eigen::Matrix3d covariance() const {
    if (!out_.count) return Eigen::Matrix3d::Zero();
    const Eigen::Vector3d m = sum_ / double(out_.count);
    return scatter_ / double(out_.count) - m * m.transpose();
  }

 private:
  template <class T>
  void hashVector(const std::vector<T>& v) {
    const uint64_t n = v.size();
    XXH3_64bits_update(hash_, &n, sizeof n);
    if (n) XXH3_64bits_update(hash_, v.data(), n * sizeof(T));
  }
  void hashBatch(const PointBatch& b) {
    hashVector(b.x), hashVector(b.y), hashVector(b.z), hashVector(b.nx), hashVector(b.ny), hashVector(b.nz);
    hashVector(b.r), hashVector(b.g), hashVector(b.b), hashVector(b.scan), hashVector(b.intensity);
    hashVector(b.confidence), hashVector(b.classification);
  }
  XXH3_state_t* hash_ = nullptr;
  BoundsInfo& out_;
  const ProgressFn& progress_;
  uint64_t total_, seen_ = 0;
  const InputSet& in_;
  bool strict_;
  Eigen::Vector3d sum_ = Eigen::Vector3d::Zero(), ref_ = Eigen::Vector3d::Zero();
  Eigen::Matrix3d scatter_ = Eigen::Matrix3d::Zero();
  bool haveColor_ = false;
  uint8_t first_[3] = {0, 0, 0};
};

// Buffers records per chunk node and appends them to the node's file when full.
class ChunkFiles {
 public:
  ChunkFiles(const std::string& dir, int level) : dir_(dir), level_(level) {}
  std::string pathOf(uint64_t key) const {
    return joinPath(dir_, "chunk_L" + std::to_string(level_) + "_" + std::to_string(key) + ".bin");
  }
  Status add(uint64_t key, const ChunkPoint& p) {
    Node& n = nodes_[key];
    n.buf.push_back(p);
    ++n.count;
    if (n.buf.size() >= kFlush) return flush(key, n);
    return Status::ok();
  }
  Status flushAll() {
    for (auto& [k, n] : nodes_) SA_RETURN_IF_ERROR(flush(k, n));
    return Status::ok();
  }
  template <class F>
  void forEach(F f) const {
    for (const auto& [k, n] : nodes_) f(k, n.count);
  }

 private:
  static constexpr size_t kFlush = 8192;  // 288 KiB per open node
  struct Node { std::vector<ChunkPoint> buf; uint64_t count = 0; };
  Status flush(uint64_t key, Node& n) {
    if (n.buf.empty()) return Status::ok();
    std::string path = pathOf(key);
    std::FILE* f = std::fopen(path.c_str(), "ab");
    if (!f) return Status::internal(path + ": cannot write chunk file: " + std::strerror(errno));
    Status st = writeFrames(f, path, n.buf.data(), n.buf.size());
    if (std::fclose(f) != 0 && st.isOk()) st = Status::internal(path + ": short write (disk full?)");
    SA_RETURN_IF_ERROR(st);
    n.buf.clear();
    n.buf.shrink_to_fit();
    return Status::ok();
  }
  std::string dir_;
  int level_;
  std::map<uint64_t, Node> nodes_;
};

uint64_t keyOf(uint32_t ix, uint32_t iy, uint32_t iz, int level) {
  return (uint64_t(ix) << (2 * level)) | (uint64_t(iy) << level) | uint64_t(iz);
}

class DistributeSink : public BatchSink {
 public:
  DistributeSink(const Quantizer& qz, const DistributeOptions& opt, ChunkFiles& files, int level,
                 DistributeResult& out, const ProgressFn& p, uint64_t total)
      : qz_(qz), opt_(opt), files_(files), level_(level), out_(out), progress_(p), total_(total) {
    if (opt_.keepTriangles) {
      out_.trianglePath = joinPath(opt_.scratchDir, "triangles.bin");
      tri_ = std::fopen(out_.trianglePath.c_str(), "wb");
    }
  }
  ~DistributeSink() override {
    if (tri_) std::fclose(tri_);
  }
  Status onPoints(const PointBatch& b) override {
    const int shift = 32 - level_;
    for (size_t i = 0; i < b.size(); ++i) {
      if (!finite3(b.x[i], b.y[i], b.z[i])) continue;
      ChunkPoint p{};
      const double rel[3] = {b.x[i] - opt_.origin.x(), b.y[i] - opt_.origin.y(), b.z[i] - opt_.origin.z()};
      for (int a = 0; a < 3; ++a) p.q[a] = qz_.encode(rel[a], a);
      if (b.hasNormals()) {
        p.n[0] = b.nx[i]; p.n[1] = b.ny[i]; p.n[2] = b.nz[i];
        p.flags |= kChunkHasNormal;
      }
      if (b.hasColors()) { p.rgb[0] = b.r[i]; p.rgb[1] = b.g[i]; p.rgb[2] = b.b[i]; }
      p.scan = b.scan.empty() ? 0 : b.scan[i];
      p.vid = static_cast<uint32_t>(b.firstIndex + i);
      if (opt_.keepTriangles) {
        if (out_.vertexPos.size() < 3 * (size_t(p.vid) + 1)) {
          out_.vertexPos.resize(3 * (size_t(p.vid) + 1), 0.0);
        }
        for (int a = 0; a < 3; ++a) out_.vertexPos[3 * size_t(p.vid) + a] = rel[a];
      }
      const uint32_t ix = level_ ? p.q[0] >> shift : 0, iy = level_ ? p.q[1] >> shift : 0,
                     iz = level_ ? p.q[2] >> shift : 0;
      SA_RETURN_IF_ERROR(files_.add(keyOf(ix, iy, iz, level_), p));
    }
    seen_ += b.size();
    if (progress_) progress_("distribute", seen_, total_);
    return Status::ok();
  }
  Status onTriangles(const uint32_t* idx, size_t n) override {
    if (!tri_) return Status::ok();
    out_.triangles += n;
    if (std::fwrite(idx, 12, n, tri_) != n) return Status::internal(out_.trianglePath + ": short write");
    // Area-weighted vertex normals (the cross product's length is twice the area).
    if (out_.vertexNormal.size() < out_.vertexPos.size()) out_.vertexNormal.resize(out_.vertexPos.size(), 0.f);
    const auto& P = out_.vertexPos;
    for (size_t t = 0; t < n; ++t) {
      const uint32_t a = idx[3 * t], b = idx[3 * t + 1], c = idx[3 * t + 2];
      if (3 * size_t(std::max({a, b, c})) + 2 >= P.size()) continue;
      Eigen::Vector3d pa(&P[3 * a]), pb(&P[3 * b]), pc(&P[3 * c]);
      Eigen::Vector3d nn = (pb - pa).cross(pc - pa);
      for (uint32_t v : {a, b, c})
        for (int k = 0; k < 3; ++k) out_.vertexNormal[3 * size_t(v) + k] += float(nn[k]);
    }
    SA_RETURN_IF_ERROR(sampleLargeTriangles(idx, n));
    triBase_ += n;
    return Status::ok();
  }

 private:
  const Quantizer& qz_;
  const DistributeOptions& opt_;
  ChunkFiles& files_;
  int level_;
  DistributeResult& out_;
  // The octree is built from points, so a triangle much larger than its neighbours (the flat
  // base of a scanned bust) would have no cell where none of its vertices lies: such triangles
  // get points sampled over them, about one median edge length apart (the median over the
  // edges seen so far, at least one batch of triangles).
  Status sampleLargeTriangles(const uint32_t* idx, size_t n) {
    const auto& P = out_.vertexPos;
    auto edge = [&](uint32_t u, uint32_t v) { return (Eigen::Vector3d(&P[3 * size_t(u)]) - Eigen::Vector3d(&P[3 * size_t(v)])).norm(); };
    for (size_t t = 0; t < n && edges_.size() < kEdgeSample; ++t) {
      const uint32_t a = idx[3 * t], b = idx[3 * t + 1];
      if (3 * size_t(std::max(a, b)) + 2 < P.size()) edges_.push_back(edge(a, b));
    }
    if (edges_.empty()) return Status::ok();
    std::vector<double> tmp(edges_);
    std::nth_element(tmp.begin(), tmp.begin() + long(tmp.size() / 2), tmp.end());
    const double median = tmp[tmp.size() / 2];
    if (!(median > 0)) return Status::ok();
    const int shift = 32 - level_;
    for (size_t t = 0; t < n; ++t) {
      const uint32_t a = idx[3 * t], b = idx[3 * t + 1], c = idx[3 * t + 2];
      if (3 * size_t(std::max({a, b, c})) + 2 >= P.size()) continue;
      const double longest = std::max({edge(a, b), edge(b, c), edge(c, a)});
      if (!(longest > kLargeEdges * median)) continue;
      const Eigen::Vector3d pa(&P[3 * a]), pb(&P[3 * b]), pc(&P[3 * c]);
      Eigen::Vector3d nn = (pb - pa).cross(pc - pa);
      if (!(nn.norm() > 0)) continue;
      nn.normalize();
      out_.surfaceSampleStep = std::max(out_.surfaceSampleStep, median);
      // A lattice about one median edge apart along AB and AC (area-proportional: a long thin
      // triangle gets few points), the corners left out (they are vertices).
      const int mb = static_cast<int>(std::min(std::ceil((pb - pa).norm() / median), 4096.0));
      const int mc = static_cast<int>(std::min(std::ceil((pc - pa).norm() / median), 4096.0));
      for (int i = 0; i <= mb; ++i)
        for (int j = 0; j <= mc; ++j) {
          const double fb = double(i) / mb, fc = double(j) / mc;
          if (fb + fc > 1 + 1e-9 || (i == 0 && j == 0) || (i == mb && j == 0) || (i == 0 && j == mc)) continue;
          const Eigen::Vector3d q = pa + (pb - pa) * fb + (pc - pa) * fc;
          ChunkPoint p{};
          for (int k = 0; k < 3; ++k) {
            p.q[k] = qz_.encode(q[k], k);
            p.n[k] = float(nn[k]);
          }
          p.flags = kChunkHasNormal | kChunkSurfaceSample;
          p.vid = static_cast<uint32_t>(triBase_ + t);
          const uint32_t ix = level_ ? p.q[0] >> shift : 0, iy = level_ ? p.q[1] >> shift : 0,
                         iz = level_ ? p.q[2] >> shift : 0;
          SA_RETURN_IF_ERROR(files_.add(keyOf(ix, iy, iz, level_), p));
          ++out_.surfaceSamples;
        }
    }
    return Status::ok();
  }

  static constexpr size_t kEdgeSample = 1 << 16;
  static constexpr double kLargeEdges = 4;  // a triangle is large beyond this many median edges
  const ProgressFn& progress_;
  uint64_t total_, seen_ = 0;
  std::FILE* tri_ = nullptr;
  std::vector<double> edges_;
  uint64_t triBase_ = 0;
};

// Streams an over-full chunk file into its eight children.
Status splitChunk(const ChunkInfo& c, const std::string& dir, std::vector<ChunkInfo>& children) {
  const int level = c.level + 1;
  ChunkFiles files(dir, level);
  std::FILE* f = std::fopen(c.path.c_str(), "rb");
  if (!f) return Status::internal(c.path + ": cannot reopen chunk file");
  std::vector<ChunkPoint> buf;
  const int shift = 32 - level;
  Status st;
  while (st.isOk()) {
    Result<bool> more = readFrame(f, c.path, buf);
    if (!more.isOk()) st = more.status();
    if (!st.isOk() || !*more) break;
    for (size_t i = 0; i < buf.size() && st.isOk(); ++i) {
      const ChunkPoint& p = buf[i];
      st = files.add(keyOf(p.q[0] >> shift, p.q[1] >> shift, p.q[2] >> shift, level), p);
    }
  }
  std::fclose(f);
  SA_RETURN_IF_ERROR(st);
  SA_RETURN_IF_ERROR(files.flushAll());
  std::remove(c.path.c_str());
  const uint64_t mask = (uint64_t(1) << level) - 1;
  files.forEach([&](uint64_t key, uint64_t count) {
    ChunkInfo ch;
    ch.path = files.pathOf(key);
    ch.count = count;
    ch.level = level;
    ch.ix = uint32_t((key >> (2 * level)) & mask);
    ch.iy = uint32_t((key >> level) & mask);
    ch.iz = uint32_t(key & mask);
    children.push_back(ch);
  });
  return Status::ok();
}

}  // namespace

Status computeBounds(const InputSet& input, BoundsInfo& out, const ProgressFn& progress, bool strict, bool hash) {
  out = BoundsInfo{};
  BoundsSink sink(out, progress, input.pointCount(), input, strict, hash);
  SA_RETURN_IF_ERROR(input.stream(sink, false));
  out.centroid = sink.centroid();
  out.covariance = sink.covariance();
  out.contentHash = sink.digest();
  if (out.count == 0) return Status::badInput(input.files()[0].path + ": no finite points in the input");
  return Status::ok();
}

Status distributePoints(const InputSet& input, const Quantizer& qz, const DistributeOptions& opt,
                        DistributeResult& out, const ProgressFn& progress) {
  // Start at the level where an even spread would fit, at most 8^3 = 512 nodes.
  int level = 0;
  const uint64_t n = input.pointCount();
  while (level < 3 && (n >> (3 * level)) > opt.maxPointsPerChunk) ++level;
  ChunkFiles files(opt.scratchDir, level);
  {
    DistributeSink sink(qz, opt, files, level, out, progress, n);
    SA_RETURN_IF_ERROR(input.stream(sink, opt.keepTriangles));
  }
  SA_RETURN_IF_ERROR(files.flushAll());
  std::vector<ChunkInfo> work;
  const uint64_t mask = (uint64_t(1) << level) - 1;
  files.forEach([&](uint64_t key, uint64_t count) {
    ChunkInfo ch;
    ch.path = files.pathOf(key);
    ch.count = count;
    ch.level = level;
    ch.ix = uint32_t((key >> (2 * level)) & mask);
    ch.iy = uint32_t((key >> level) & mask);
    ch.iz = uint32_t(key & mask);
    work.push_back(ch);
  });
  while (!work.empty()) {
    ChunkInfo c = work.back();
    work.pop_back();
    if (c.count > opt.maxPointsPerChunk && c.level < opt.maxChunkLevel) {
      SA_RETURN_IF_ERROR(splitChunk(c, opt.scratchDir, work));
    } else {
      out.chunks.push_back(c);
    }
  }
  return Status::ok();
}

Status loadChunk(const ChunkInfo& chunk, std::vector<ChunkPoint>& out) {
  out.clear();
  out.reserve(chunk.count);
  std::FILE* f = std::fopen(chunk.path.c_str(), "rb");
  if (!f) return Status::internal(chunk.path + ": cannot open chunk file");
  std::vector<ChunkPoint> frame;
  Status st;
  while (st.isOk()) {
    Result<bool> more = readFrame(f, chunk.path, frame);
    if (!more.isOk()) st = more.status();
    if (!st.isOk() || !*more) break;
    if (out.size() + frame.size() > chunk.count) st = Status::internal(chunk.path + ": chunk file longer than recorded");
    else out.insert(out.end(), frame.begin(), frame.end());
  }
  std::fclose(f);
  SA_RETURN_IF_ERROR(st);
  if (out.size() != chunk.count) return Status::internal(chunk.path + ": chunk file shorter than recorded");
  return Status::ok();
}

Status saveChunk(const std::string& path, const std::vector<ChunkPoint>& points) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return Status::internal(path + ": cannot write chunk file");
  Status st = writeFrames(f, path, points.data(), points.size());
  if (std::fclose(f) != 0 && st.isOk()) st = Status::internal(path + ": short write (disk full?)");
  return st;
}

uint64_t chunkBytesWritten() { return gScratchBytes.load(); }
uint64_t chunkRecordBytesWritten() { return gScratchRaw.load(); }

}  // namespace sa

