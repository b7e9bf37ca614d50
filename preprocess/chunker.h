// Out-of-core stage, after PotreeConverter 2's count -> chunk scheme: one pass computes the
// bounds, a second distributes points into on-disk chunk files, each an octree node small
// enough (maxPointsPerChunk) to be processed in memory. Over-full chunks are re-split by
// streaming their file into eight children.
#pragma once
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/raw_vector.h"
#include "formats/source.h"

namespace sa {

// On-disk chunk record. Positions are integers relative to the root cube (see Quantizer);
// never absolute floats.
struct ChunkPoint {
  uint32_t q[3];
  float n[3];
  uint8_t rgb[3];
  uint8_t flags;
  uint16_t scan;
  uint16_t spacing;  // pass A: the point's local spacing over its chunk's, x 1024 (0: unknown)
  uint32_t vid;  // index of the point in its file (mesh vertex index for the triangle path)
};
static_assert(sizeof(ChunkPoint) == 36);

// A chunk's records in memory: resized without zeroing (common/raw_vector.h), since the loops
// that fill them (frames decoded on every core, records gathered) write every one.
using ChunkRecords = RawVector<ChunkPoint>;

// Fraction bits a normal component keeps in the chunk files between passes A and B: its low
// mantissa bytes become zero and compress to nothing.
constexpr int kChunkNormalBits = 15;

// A normal component rounded to a multiple of 2^-kChunkNormalBits: the bits of
// std::ldexp(std::nearbyint(std::ldexp(v, kChunkNormalBits)), -kChunkNormalBits) (every float
// checked once) without three libm calls. Scaling by a power of two is exact here; adding and
// subtracting 2^23 rounds a magnitude under 2^23 to the nearest integer, ties to even, as
// nearbyint in the default rounding mode; copysign keeps nearbyint's sign (-0 for a small
// negative). A magnitude past 2^23, infinities and NaN (not a unit normal's) take the calls.
inline float roundToChunkNormal(float v) {
  constexpr float kScale = float(1 << kChunkNormalBits), kBig = 8388608.0f;  // 2^23
  const float a = std::abs(v) * kScale;
  if (!(a < kBig)) return std::ldexp(std::nearbyint(std::ldexp(v, kChunkNormalBits)), -kChunkNormalBits);
  return std::copysign((a + kBig) - kBig, v) / kScale;
}

// ChunkPoint::flags bits.
enum ChunkFlags : uint8_t {
  kChunkHasNormal = 1,
  // A point sampled on a large triangle (triangle path), not an input vertex: vid is the
  // triangle's index. Large triangles get cells where none of their vertices lies.
  kChunkSurfaceSample = 2,
  // Pass A's fit found a clean surface around the point (SurfaceOptions::surfaceLike): its splat
  // and coverage radii may follow its spacing past the pack's (pipeline.cpp, sampleScale).
  kChunkSurfaceLike = 4,
};

// Maps positions relative to the pack origin to 32-bit integers over the root cube.
struct Quantizer {
  Eigen::Vector3d cubeMin = Eigen::Vector3d::Zero();  // relative to the pack origin
  double cubeSize = 1;
  uint32_t encode(double v, int axis) const {
    double t = (v - cubeMin[axis]) / cubeSize * 4294967296.0;
    if (!(t > 0)) return 0;
    if (t >= 4294967295.0) return 4294967295u;
    return static_cast<uint32_t>(t);
  }
  double decode(uint32_t q, int axis) const { return cubeMin[axis] + (q + 0.5) * (cubeSize / 4294967296.0); }
};

struct BoundsInfo {
  Eigen::Vector3d min = Eigen::Vector3d::Constant(1e300), max = Eigen::Vector3d::Constant(-1e300);
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  // absolute
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // of the positions
  uint64_t count = 0;    // finite points
  uint64_t skipped = 0;  // NaN / Inf coordinates
  bool colorVaries = false;  // some two points differ in colour (constant colour is no colour)
  uint64_t contentHash = 0;  // XXH3 of every batch's attributes as read (computeBounds with hash)
};

struct ChunkInfo {
  std::string path;
  uint64_t count = 0;
  int level = 0;              // octree level of the chunk's node
  uint32_t ix = 0, iy = 0, iz = 0;  // node coordinates at that level
  // DistributeOptions::inMemory: the chunk's records, held in memory instead of in the file at
  // `path` (never written). loadChunk hands them over; saveChunk gives them back.
  std::shared_ptr<ChunkRecords> held;
};

using ProgressFn = std::function<void(const char* phase, uint64_t done, uint64_t total)>;

// Pass 1: bounds, centroid, finite / skipped counts. strict: a NaN/Inf coordinate is an error
// naming the file and the point, instead of being skipped and counted. hash: also hash every
// point's attributes as they stream by (out.contentHash), so packing reads its input once for
// both (the up-to-date check).
Status computeBounds(const InputSet& input, BoundsInfo& out, const ProgressFn& progress, bool strict = false,
                     bool hash = false);

// The node's cube, relative to the pack origin.
inline void nodeCube(const Quantizer& qz, int level, uint32_t ix, uint32_t iy, uint32_t iz,
                     Eigen::Vector3d& min, double& size) {
  size = qz.cubeSize / double(1u << level);
  min = qz.cubeMin + Eigen::Vector3d(ix, iy, iz) * size;
}

struct DistributeOptions {
  uint64_t maxPointsPerChunk = 4u << 20;
  int maxChunkLevel = 10;
  std::string scratchDir;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // pack origin (absolute)
  bool keepTriangles = false;                        // also write triangles.bin
  // Point inputs that may fill more than one chunk: count the points per node in a first read,
  // so that every point goes straight to its final chunk and no chunk file is split (the same
  // chunks as splitting, in the same order).
  bool plan = true;
  // A point input that fits one chunk (at most maxPointsPerChunk points) keeps its records in
  // memory (ChunkInfo::held) instead of coding, writing and rereading a chunk file twice: the
  // records are those passes A and B load anyway. One process only: a cluster's ranks read
  // chunk files.
  bool inMemory = false;
};

struct DistributeResult {
  std::vector<ChunkInfo> chunks;
  uint64_t triangles = 0;
  uint64_t surfaceSamples = 0;  // points sampled on large triangles (kChunkSurfaceSample)
  double surfaceSampleStep = 0;  // their lattice step (0: none)
  std::string trianglePath;  // u32 triples, when keepTriangles
  // Mesh vertices (triangle path only): positions relative to the pack origin and
  // area-weighted normals, indexed by vertex id.
  std::vector<double> vertexPos;
  std::vector<float> vertexNormal;
  std::vector<float> vertexCone;  // vertexNormalCones (triangle_cells.h), filled by the pipeline
};

// Pass 2: writes chunk files into options.scratchDir.
Status distributePoints(const InputSet& input, const Quantizer& qz, const DistributeOptions& options,
                        DistributeResult& out, const ProgressFn& progress);

// Reads a chunk file whole, or takes a held chunk's records (ChunkInfo::held; a second load
// without a save between is an error).
// Chunk files hold frames of byte-shuffled, zstd-compressed records (chunker.cpp).
Status loadChunk(const ChunkInfo& chunk, ChunkRecords& out);
Status saveChunk(const std::string& path, std::span<const ChunkPoint> points);
// Writes the chunk's file, or hands a held chunk the records.
Status saveChunk(const ChunkInfo& chunk, ChunkRecords&& points);
// Bytes written to chunk files by this process so far (the summary's temporary bytes).
uint64_t chunkBytesWritten();
// The same records uncompressed (36 bytes each).
uint64_t chunkRecordBytesWritten();

}  // namespace sa
