#include "preprocess/chunker.h"

#include <xxhash.h>
#include <zstd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <algorithm>
#include <atomic>
#include <bit>
#include <map>
#include <memory>

#include <Eigen/Geometry>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "atlas/zstd_context.h"
#include "common/fileio.h"

namespace sa {
namespace {

// ---- chunk files: frames of compressed records ----
// A chunk file is a sequence of frames: u32 record count (1..kMaxFrameRecords), u32 compressed
// bytes, u32 position shifts, then the records with their positions as differences
// (deltaPositions), byte-shuffled (byte b of every record together: positions, normals and ids
// compress far better as planes) and zstd-compressed at level 1. Packing writes and rereads
// every point two or three times; raw 36-byte records made the temporary files twice the input.
constexpr uint32_t kMaxFrameRecords = 1u << 16;
std::atomic<uint64_t> gScratchBytes{0}, gScratchRaw{0};

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

// Positions as zigzagged differences from the record before (the frame's first from zero), per
// axis, after shifting out the low bits every position of the frame has zero (`shift`, the
// frame header's third word: pass A rounds a point chunk's positions to a step under its
// sample spacing). Records in cell order, or in a scanner's order, lie close to the one before:
// a difference's high bytes are then zero planes where the 32-bit positions' were noise.
uint32_t zeroBits(const ChunkPoint* r, size_t m) {
  uint32_t any[3] = {0, 0, 0}, shift = 0;
  for (size_t i = 0; i < m; ++i)
    for (int a = 0; a < 3; ++a) any[a] |= r[i].q[a];
  for (int a = 0; a < 3; ++a) shift |= uint32_t(any[a] ? std::countr_zero(any[a]) : 0) << (8 * a);
  return shift;
}
void deltaPositions(ChunkPoint* r, size_t m, uint32_t shift) {
  uint32_t prev[3] = {0, 0, 0};
  for (size_t i = 0; i < m; ++i)
    for (int a = 0; a < 3; ++a) {
      const uint32_t q = r[i].q[a] >> ((shift >> (8 * a)) & 31);
      const uint32_t d = q - prev[a];
      prev[a] = q;
      r[i].q[a] = (d << 1) ^ (0u - (d >> 31));
    }
}
void undeltaPositions(ChunkPoint* r, size_t m, uint32_t shift) {
  uint32_t prev[3] = {0, 0, 0};
  for (size_t i = 0; i < m; ++i)
    for (int a = 0; a < 3; ++a) {
      const uint32_t z = r[i].q[a];
      prev[a] += (z >> 1) ^ (0u - (z & 1u));
      r[i].q[a] = prev[a] << ((shift >> (8 * a)) & 31);
    }
}

// One frame of m records coded into out (its header, then the zstd stream); error set when zstd
// fails.
void encodeFrame(const ChunkPoint* pts, size_t m, std::vector<uint8_t>& out, std::string& error) {
  ZSTD_CCtx* cctx = threadZstd().c;
  thread_local std::vector<uint8_t> planes;
  thread_local std::vector<ChunkPoint> frame;
  frame.assign(pts, pts + m);
  const uint32_t shift = zeroBits(frame.data(), m);
  deltaPositions(frame.data(), m, shift);
  planes.resize(m * kRec);
  shuffleRecords(reinterpret_cast<const uint8_t*>(frame.data()), m, planes.data());
  constexpr size_t kHead = 12;
  out.resize(kHead + ZSTD_compressBound(planes.size()));
  const size_t c = ZSTD_compressCCtx(cctx, out.data() + kHead, out.size() - kHead, planes.data(), planes.size(), 1);
  if (ZSTD_isError(c)) {
    error = ZSTD_getErrorName(c);
    return;
  }
  const uint32_t head[3] = {uint32_t(m), uint32_t(c), shift};
  std::memcpy(out.data(), head, kHead);
  out.resize(kHead + c);
}

// Frames are coded on every core, a few per thread at a time, and written in order: the bytes
// are those of coding them one after the other.
Status writeFrames(std::FILE* f, const std::string& path, const ChunkPoint* pts, size_t n) {
  const size_t frames = (n + kMaxFrameRecords - 1) / kMaxFrameRecords;
  const size_t batch = 2 * size_t(std::max(1, tbb::this_task_arena::max_concurrency()));
  std::vector<std::vector<uint8_t>> coded(std::min(frames, batch));
  std::vector<std::string> errors(coded.size());
  for (size_t first = 0; first < frames; first += batch) {
    const size_t count = std::min(batch, frames - first);
    tbb::parallel_for(size_t(0), count, [&](size_t b) {
      const size_t at = (first + b) * kMaxFrameRecords, m = std::min<size_t>(kMaxFrameRecords, n - at);
      encodeFrame(pts + at, m, coded[b], errors[b]);
    });
    for (size_t b = 0; b < count; ++b) {
      if (!errors[b].empty()) return Status::internal(path + ": cannot compress a chunk frame: " + errors[b]);
      if (std::fwrite(coded[b].data(), 1, coded[b].size(), f) != coded[b].size())
        return Status::internal(path + ": short write (disk full?)");
      gScratchBytes += coded[b].size();
      gScratchRaw += std::min<size_t>(kMaxFrameRecords, n - (first + b) * kMaxFrameRecords) * kRec;
    }
  }
  return Status::ok();
}

// A frame as stored: its header {records, coded bytes, shift} and its zstd stream.
struct CodedFrame {
  uint32_t head[3] = {0, 0, 0};
  std::vector<uint8_t> packed;
};

// Reads the next frame's header and coded bytes; false at the end of the file. A header out of
// range or a short frame is an error naming the file.
Result<bool> readCodedFrame(std::FILE* f, const std::string& path, CodedFrame& out) {
  uint32_t* head = out.head;
  const size_t got = std::fread(head, 4, 3, f);
  if (got == 0 && std::feof(f)) return false;
  if (got != 3 || head[0] == 0 || head[0] > kMaxFrameRecords || head[1] > ZSTD_compressBound(size_t(head[0]) * kRec) ||
      (head[2] & 0xe0e0e0e0u) != 0)
    return Status::internal(path + ": chunk file is damaged (a frame header out of range)");
  out.packed.resize(head[1]);
  if (std::fread(out.packed.data(), 1, head[1], f) != head[1]) return Status::internal(path + ": chunk file is truncated");
  return true;
}

// Decodes a frame's head[0] records into dst; false when they do not decode.
bool decodeFrame(const CodedFrame& in, ChunkPoint* dst) {
  thread_local std::vector<uint8_t> planes;
  const size_t m = in.head[0];
  planes.resize(m * kRec);
  const size_t d = ZSTD_decompressDCtx(threadZstd().d, planes.data(), planes.size(), in.packed.data(), in.packed.size());
  if (ZSTD_isError(d) || d != planes.size()) return false;
  unshuffleRecords(planes.data(), m, reinterpret_cast<uint8_t*>(dst));
  undeltaPositions(dst, m, in.head[2]);
  return true;
}

// Reads the next frame into out (replacing it); false at the end of the file. A frame that does
// not decode (a truncated or foreign file) is an error naming the file.
Result<bool> readFrame(std::FILE* f, const std::string& path, std::vector<ChunkPoint>& out) {
  thread_local CodedFrame coded;
  Result<bool> more = readCodedFrame(f, path, coded);
  if (!more.isOk() || !*more) return more;
  out.resize(coded.head[0]);
  if (!decodeFrame(coded, out.data())) return Status::internal(path + ": chunk file is damaged (a frame does not decode)");
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

// An octree node: level and key (keyOf) in one number.
uint64_t nodeId(int level, uint64_t key) { return (uint64_t(level) << 40) | key; }
int levelOfNode(uint64_t id) { return int(id >> 40); }
uint64_t keyOfNode(uint64_t id) { return id & ((uint64_t(1) << 40) - 1); }

ChunkInfo chunkInfoOf(const std::string& path, uint64_t id, uint64_t count) {
  ChunkInfo ch;
  ch.path = path;
  ch.count = count;
  ch.level = levelOfNode(id);
  const uint64_t key = keyOfNode(id), mask = (uint64_t(1) << ch.level) - 1;
  ch.ix = uint32_t((key >> (2 * ch.level)) & mask);
  ch.iy = uint32_t((key >> ch.level) & mask);
  ch.iz = uint32_t(key & mask);
  return ch;
}

// Buffers records per chunk node (nodeId) and appends them to the node's file when full. Full
// buffers wait until a few per thread are full, are coded on every core and appended in the
// order they filled: each file's bytes are those of appending them one at a time.
// With `hold` records (DistributeOptions::inMemory), each node keeps its records in memory instead
// (ChunkInfo::held), space for `hold` reserved when its first record comes.
class ChunkFiles {
 public:
  explicit ChunkFiles(const std::string& dir, uint64_t hold = 0)
      : dir_(dir), batch_(2 * size_t(std::max(1, tbb::this_task_arena::max_concurrency()))), hold_(hold) {}
  std::string pathOf(uint64_t id) const {
    return joinPath(dir_, "chunk_L" + std::to_string(levelOfNode(id)) + "_" + std::to_string(keyOfNode(id)) + ".bin");
  }
  Status add(uint64_t key, const ChunkPoint& p) {
    Node& n = node(key);
    ++n.count;
    if (hold_) {
      n.held->push_back(p);
      return Status::ok();
    }
    n.buf.push_back(p);
    if (n.buf.size() >= kFlush) return flush(key, n);
    return Status::ok();
  }
  // A batch's records in order, to the nodes `keys` name (`skip`: to none). Held records of one
  // node, none skipped (a batch of a one-chunk input without NaN): copied on every core, so
  // that their first touch of the held chunk's pages is not on one core.
  Status addBatch(const uint64_t* keys, const ChunkPoint* recs, size_t m, uint64_t skip) {
    if (hold_ && m > 0 && keys[0] != skip && std::all_of(keys, keys + m, [&](uint64_t k) { return k == keys[0]; })) {
      Node& n = node(keys[0]);
      const size_t at = n.held->size();
      n.held->resize(at + m);
      ChunkPoint* dst = n.held->data() + at;
      tbb::parallel_for(tbb::blocked_range<size_t>(0, m, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
        std::copy(recs + r.begin(), recs + r.end(), dst + r.begin());
      });
      n.count += m;
      return Status::ok();
    }
    for (size_t i = 0; i < m; ++i)
      if (keys[i] != skip) SA_RETURN_IF_ERROR(add(keys[i], recs[i]));
    return Status::ok();
  }
  std::shared_ptr<ChunkRecords> heldOf(uint64_t id) const {
    const auto it = nodes_.find(id);
    return it == nodes_.end() ? nullptr : it->second.held;
  }
  Status flushAll() {
    for (auto& [k, n] : nodes_) SA_RETURN_IF_ERROR(flush(k, n));
    return writePending();
  }
  template <class F>
  void forEach(F f) const {
    for (const auto& [k, n] : nodes_) f(k, n.count);
  }

 private:
  static constexpr size_t kFlush = 8192;  // 288 KiB per open node
  struct Node {
    std::vector<ChunkPoint> buf;
    uint64_t count = 0;
    std::shared_ptr<ChunkRecords> held;
  };
  struct Full {
    uint64_t key;
    std::vector<ChunkPoint> buf;
    std::vector<uint8_t> coded;
    std::string error;
  };
  // The node of `key`, with its held records' space reserved.
  Node& node(uint64_t key) {
    if (!last_ || key != lastKey_) {  // points come in runs of one node (a scan's order, a split chunk's)
      last_ = &nodes_[key];
      lastKey_ = key;
    }
    if (hold_ && !last_->held) {
      last_->held = std::make_shared<ChunkRecords>();
      last_->held->reserve(hold_);
    }
    return *last_;
  }
  Status flush(uint64_t key, Node& n) {
    if (n.buf.empty()) return Status::ok();
    pending_.push_back({key, std::move(n.buf), {}, {}});
    n.buf = {};
    return pending_.size() >= batch_ ? writePending() : Status::ok();
  }
  Status writePending() {
    tbb::parallel_for(size_t(0), pending_.size(), [&](size_t i) {
      Full& w = pending_[i];
      encodeFrame(w.buf.data(), w.buf.size(), w.coded, w.error);
    });
    for (Full& w : pending_) {
      const std::string path = pathOf(w.key);
      if (!w.error.empty()) return Status::internal(path + ": cannot compress a chunk frame: " + w.error);
      std::FILE* f = std::fopen(path.c_str(), "ab");
      if (!f) return Status::internal(path + ": cannot write chunk file: " + std::strerror(errno));
      const bool full = std::fwrite(w.coded.data(), 1, w.coded.size(), f) == w.coded.size();
      if (std::fclose(f) != 0 || !full) return Status::internal(path + ": short write (disk full?)");
      gScratchBytes += w.coded.size();
      gScratchRaw += w.buf.size() * kRec;
    }
    pending_.clear();
    return Status::ok();
  }
  std::string dir_;
  size_t batch_;
  uint64_t hold_;
  std::map<uint64_t, Node> nodes_;
  std::vector<Full> pending_;
  Node* last_ = nullptr;
  uint64_t lastKey_ = 0;
};

uint64_t keyOf(uint32_t ix, uint32_t iy, uint32_t iz, int level) {
  return (uint64_t(ix) << (2 * level)) | (uint64_t(iy) << level) | uint64_t(iz);
}

// A point's quantized position (Quantizer over the root cube, relative to the pack origin) and
// the key of its node at a level.
void quantize(const PointBatch& b, size_t i, const Quantizer& qz, const Eigen::Vector3d& origin, uint32_t q[3]) {
  const double rel[3] = {b.x[i] - origin.x(), b.y[i] - origin.y(), b.z[i] - origin.z()};
  for (int a = 0; a < 3; ++a) q[a] = qz.encode(rel[a], a);
}
uint64_t keyAt(const uint32_t q[3], int level) {
  if (level == 0) return 0;
  const int shift = 32 - level;
  return keyOf(q[0] >> shift, q[1] >> shift, q[2] >> shift, level);
}

// ---- the chunk plan: the chunks known before any point is written ----
// Splitting an over-full chunk file rewrites its points (a third of a 100 M-point pack's
// temporary bytes). Where the input may hold more points than one chunk takes, a counting pass
// over the input first gives the points per node down to kPlanLevel, and each point then goes
// straight to the chunk the split loop of distributePoints would have ended with: the same
// chunks, in the same order, each file written once (a node still over-full at kPlanLevel is
// split as before).
constexpr int kPlanLevel = 6;  // 8^6 counters: 2 MiB

class HistogramSink : public BatchSink {
 public:
  HistogramSink(const Quantizer& qz, const Eigen::Vector3d& origin, int level, const ProgressFn& p, uint64_t total)
      : qz_(qz), origin_(origin), level_(level), counts_(size_t(1) << (3 * level), 0), progress_(p), total_(total) {}
  // The nodes found on every core, counted in order.
  Status onPoints(const PointBatch& b) override {
    keys_.resize(b.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, b.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i != r.end(); ++i) {
        uint32_t q[3];
        quantize(b, i, qz_, origin_, q);
        keys_[i] = finite3(b.x[i], b.y[i], b.z[i]) ? keyAt(q, level_) : kSkipped;
      }
    });
    for (uint64_t k : keys_)
      if (k != kSkipped) ++counts_[k];
    seen_ += b.size();
    if (progress_) progress_("distribute", seen_ / 2, total_);
    return Status::ok();
  }
  std::vector<uint64_t>& counts() { return counts_; }

 private:
  static constexpr uint64_t kSkipped = UINT64_MAX;  // a NaN or infinite point
  std::vector<uint64_t> keys_;
  const Quantizer& qz_;
  Eigen::Vector3d origin_;
  int level_;
  std::vector<uint64_t> counts_;
  const ProgressFn& progress_;
  uint64_t total_, seen_ = 0;
};

struct ChunkPlan {
  int level = 0;                // kPlanLevel or the deepest chunk level, if shallower
  std::vector<uint64_t> leafOf;  // per node at `level`: the nodeId of the chunk that holds it
  std::vector<uint64_t> leaves;  // the chunks (nodeId) in the order the split loop ends with them
  uint64_t nodeOf(const uint32_t q[3]) const { return leafOf[keyAt(q, level)]; }
};

// The plan from the points per node at plan.level (`counts`), starting at `start` as
// distributePoints does.
ChunkPlan planChunks(std::vector<uint64_t> counts, int H, int start, const DistributeOptions& opt) {
  std::vector<std::vector<uint64_t>> cnt(size_t(H) + 1);
  cnt[size_t(H)] = std::move(counts);
  for (int l = H - 1; l >= start; --l) {
    cnt[size_t(l)].assign(size_t(1) << (3 * l), 0);
    const uint32_t side = 1u << (l + 1);
    for (uint32_t x = 0; x < side; ++x)
      for (uint32_t y = 0; y < side; ++y)
        for (uint32_t z = 0; z < side; ++z)
          cnt[size_t(l)][keyOf(x / 2, y / 2, z / 2, l)] += cnt[size_t(l) + 1][keyOf(x, y, z, l + 1)];
  }
  ChunkPlan plan;
  plan.level = H;
  std::vector<uint64_t> stack;
  for (uint64_t k = 0; k < cnt[size_t(start)].size(); ++k)
    if (cnt[size_t(start)][k]) stack.push_back(nodeId(start, k));
  while (!stack.empty()) {
    const uint64_t id = stack.back();
    stack.pop_back();
    const int l = levelOfNode(id);
    const uint64_t key = keyOfNode(id), mask = (uint64_t(1) << l) - 1;
    if (cnt[size_t(l)][key] <= opt.maxPointsPerChunk || l >= opt.maxChunkLevel || l >= H) {
      plan.leaves.push_back(id);
      continue;
    }
    const uint32_t ix = uint32_t((key >> (2 * l)) & mask), iy = uint32_t((key >> l) & mask), iz = uint32_t(key & mask);
    for (uint32_t d = 0; d < 8; ++d) {  // ascending child keys: x, then y, then z
      const uint64_t child = keyOf(2 * ix + (d >> 2), 2 * iy + ((d >> 1) & 1), 2 * iz + (d & 1), l + 1);
      if (cnt[size_t(l) + 1][child]) stack.push_back(nodeId(l + 1, child));
    }
  }
  plan.leafOf.assign(size_t(1) << (3 * H), 0);
  for (uint64_t id : plan.leaves) {
    const int l = levelOfNode(id);
    const uint64_t key = keyOfNode(id), mask = (uint64_t(1) << l) - 1;
    const uint32_t s = 1u << (H - l);
    const uint32_t x0 = uint32_t((key >> (2 * l)) & mask) * s, y0 = uint32_t((key >> l) & mask) * s,
                   z0 = uint32_t(key & mask) * s;
    for (uint32_t x = x0; x < x0 + s; ++x)
      for (uint32_t y = y0; y < y0 + s; ++y)
        for (uint32_t z = z0; z < z0 + s; ++z) plan.leafOf[keyOf(x, y, z, H)] = id;
  }
  return plan;
}

class DistributeSink : public BatchSink {
 public:
  DistributeSink(const Quantizer& qz, const DistributeOptions& opt, ChunkFiles& files, int level, const ChunkPlan* plan,
                 DistributeResult& out, const ProgressFn& p, uint64_t total)
      : qz_(qz), opt_(opt), files_(files), level_(level), plan_(plan), out_(out), progress_(p), total_(total) {
    if (opt_.keepTriangles) {
      out_.trianglePath = joinPath(opt_.scratchDir, "triangles.bin");
      tri_ = std::fopen(out_.trianglePath.c_str(), "wb");
    }
  }
  ~DistributeSink() override {
    if (tri_) std::fclose(tri_);
  }
  // The records and their chunks are made on every core; they go to their chunks' buffers in
  // the batch's order.
  Status onPoints(const PointBatch& b) override {
    const size_t m = b.size();
    if (opt_.keepTriangles) keepVertices(b);
    recs_.resize(m);
    chunkOf_.resize(m);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, m, 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i != r.end(); ++i) {
        if (!finite3(b.x[i], b.y[i], b.z[i])) {
          chunkOf_[i] = kSkipped;
          continue;
        }
        ChunkPoint& p = recs_[i];
        p = ChunkPoint{};
        quantize(b, i, qz_, opt_.origin, p.q);
        if (b.hasNormals()) {
          p.n[0] = b.nx[i]; p.n[1] = b.ny[i]; p.n[2] = b.nz[i];
          p.flags |= kChunkHasNormal;
        }
        if (b.hasColors()) { p.rgb[0] = b.r[i]; p.rgb[1] = b.g[i]; p.rgb[2] = b.b[i]; }
        p.scan = b.scan.empty() ? 0 : b.scan[i];
        p.vid = static_cast<uint32_t>(b.firstIndex + i);
        chunkOf_[i] = nodeOf(p.q);
      }
    });
    SA_RETURN_IF_ERROR(files_.addBatch(chunkOf_.data(), recs_.data(), m, kSkipped));
    seen_ += m;
    if (progress_) progress_("distribute", plan_ ? total_ / 2 + seen_ / 2 : seen_, total_);
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
  // Mesh vertices' positions, by index, for the triangles that follow.
  void keepVertices(const PointBatch& b) {
    for (size_t i = 0; i < b.size(); ++i) {
      if (!finite3(b.x[i], b.y[i], b.z[i])) continue;
      const size_t vid = static_cast<uint32_t>(b.firstIndex + i);
      if (out_.vertexPos.size() < 3 * (vid + 1)) out_.vertexPos.resize(3 * (vid + 1), 0.0);
      const double rel[3] = {b.x[i] - opt_.origin.x(), b.y[i] - opt_.origin.y(), b.z[i] - opt_.origin.z()};
      for (int a = 0; a < 3; ++a) out_.vertexPos[3 * vid + a] = rel[a];
    }
  }
  static constexpr uint64_t kSkipped = UINT64_MAX;  // a NaN or infinite point: no node
  std::vector<ChunkPoint> recs_;
  std::vector<uint64_t> chunkOf_;
  // The chunk node a point goes to: the plan's chunk holding it, else its node at the start level.
  uint64_t nodeOf(const uint32_t q[3]) const { return plan_ ? plan_->nodeOf(q) : nodeId(level_, keyAt(q, level_)); }
  const Quantizer& qz_;
  const DistributeOptions& opt_;
  ChunkFiles& files_;
  int level_;
  const ChunkPlan* plan_;
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
          SA_RETURN_IF_ERROR(files_.add(nodeOf(p.q), p));
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
  ChunkFiles files(dir);
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
      st = files.add(nodeId(level, keyOf(p.q[0] >> shift, p.q[1] >> shift, p.q[2] >> shift, level)), p);
    }
  }
  std::fclose(f);
  SA_RETURN_IF_ERROR(st);
  SA_RETURN_IF_ERROR(files.flushAll());
  std::remove(c.path.c_str());
  files.forEach([&](uint64_t id, uint64_t count) { children.push_back(chunkInfoOf(files.pathOf(id), id, count)); });
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
  // A mesh's surface samples appear while it streams: no plan for meshes.
  std::unique_ptr<ChunkPlan> plan;
  const int planLevel = std::min(kPlanLevel, opt.maxChunkLevel);
  if (opt.plan && !opt.keepTriangles && n > opt.maxPointsPerChunk && planLevel > level) {
    HistogramSink hist(qz, opt.origin, planLevel, progress, n);
    SA_RETURN_IF_ERROR(input.stream(hist, false));
    plan = std::make_unique<ChunkPlan>(planChunks(std::move(hist.counts()), planLevel, level, opt));
  }
  // In memory: one node (level 0: the input fits one chunk), whose records passes A and B hold anyway.
  const bool hold = opt.inMemory && !opt.keepTriangles && n <= opt.maxPointsPerChunk;
  ChunkFiles files(opt.scratchDir, hold ? std::max<uint64_t>(n, 1) : 0);
  {
    DistributeSink sink(qz, opt, files, level, plan.get(), out, progress, n);
    SA_RETURN_IF_ERROR(input.stream(sink, opt.keepTriangles));
  }
  SA_RETURN_IF_ERROR(files.flushAll());
  // The split loop pops from the back: the planned chunks go in reversed, so that it meets them
  // in the plan's order.
  std::vector<ChunkInfo> work;
  std::map<uint64_t, uint64_t> counts;
  files.forEach([&](uint64_t id, uint64_t count) { counts[id] = count; });
  if (plan) {
    for (auto it = plan->leaves.rbegin(); it != plan->leaves.rend(); ++it)
      if (counts.count(*it)) work.push_back(chunkInfoOf(files.pathOf(*it), *it, counts[*it]));
    if (work.size() != counts.size())
      return Status::badInput(input.files()[0].path + ": the input changed while it was packed (its points per region differ between two reads)");
  } else {
    for (const auto& [id, count] : counts) {
      work.push_back(chunkInfoOf(files.pathOf(id), id, count));
      work.back().held = files.heldOf(id);
    }
  }
  while (!work.empty()) {
    ChunkInfo c = work.back();
    work.pop_back();
    if (c.count > opt.maxPointsPerChunk && c.level < opt.maxChunkLevel) {
      if (c.held)  // held only when the first read counted few enough points
        return Status::badInput(input.files()[0].path + ": the input changed while it was packed (it has more points than when they were counted)");
      SA_RETURN_IF_ERROR(splitChunk(c, opt.scratchDir, work));
    } else {
      out.chunks.push_back(c);
    }
  }
  return Status::ok();
}

// Frames are read in batches, a few per thread, and decoded on every core into their places.
Status loadChunk(const ChunkInfo& chunk, ChunkRecords& out) {
  if (chunk.held) {
    if (chunk.held->size() != chunk.count)
      return Status::internal(chunk.path + ": the chunk held in memory was already handed over");
    out.swap(*chunk.held);
    ChunkRecords().swap(*chunk.held);
    return Status::ok();
  }
  out.clear();
  out.reserve(chunk.count);
  std::FILE* f = std::fopen(chunk.path.c_str(), "rb");
  if (!f) return Status::internal(chunk.path + ": cannot open chunk file");
  std::vector<CodedFrame> batch(2 * size_t(std::max(1, tbb::this_task_arena::max_concurrency())));
  Status st;
  for (bool more = true; more && st.isOk();) {
    size_t count = 0;
    for (; count < batch.size(); ++count) {
      Result<bool> r = readCodedFrame(f, chunk.path, batch[count]);
      if (!r.isOk()) st = r.status();
      if (!st.isOk() || !*r) {
        more = false;
        break;
      }
    }
    if (!st.isOk()) break;
    std::vector<size_t> at(count + 1, out.size());
    for (size_t b = 0; b < count; ++b) at[b + 1] = at[b] + batch[b].head[0];
    if (at[count] > chunk.count) {
      st = Status::internal(chunk.path + ": chunk file longer than recorded");
      break;
    }
    out.resize(at[count]);
    std::atomic<bool> bad{false};
    tbb::parallel_for(size_t(0), count, [&](size_t b) {
      if (!decodeFrame(batch[b], out.data() + at[b])) bad = true;
    });
    if (bad) st = Status::internal(chunk.path + ": chunk file is damaged (a frame does not decode)");
  }
  std::fclose(f);
  SA_RETURN_IF_ERROR(st);
  if (out.size() != chunk.count) return Status::internal(chunk.path + ": chunk file shorter than recorded");
  return Status::ok();
}

Status saveChunk(const std::string& path, std::span<const ChunkPoint> points) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return Status::internal(path + ": cannot write chunk file");
  Status st = writeFrames(f, path, points.data(), points.size());
  if (std::fclose(f) != 0 && st.isOk()) st = Status::internal(path + ": short write (disk full?)");
  return st;
}

Status saveChunk(const ChunkInfo& chunk, ChunkRecords&& points) {
  if (!chunk.held) return saveChunk(chunk.path, points);
  *chunk.held = std::move(points);
  return Status::ok();
}

uint64_t chunkBytesWritten() { return gScratchBytes.load(); }
uint64_t chunkRecordBytesWritten() { return gScratchRaw.load(); }

}  // namespace sa

