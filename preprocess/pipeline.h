// `scanatlas pack`: input files -> out-of-core chunks -> octree height fields -> height maps
// -> pack file. Memory is bounded by PackOptions::memBudget for point inputs.
#pragma once
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "atlas/tile_codec.h"
#include "formats/source.h"
#include "preprocess/chunker.h"
#include "preprocess/octree.h"

namespace sa {

// The default precision: a point cloud's heights and normals are averages of noisy samples,
// whose noise is far above 1/32 texel and a degree or more from texel to texel (1.5 degrees of
// snapping left the bunny and dragon scans' normals closer to the reference meshes than 1 and
// 0: BENCHMARKS.md, "Temporary disk and pack bytes"); a mesh's are
// exact, and kept: the accuracy tests hold its heights to 1e-5 of the model's size (1/16 texel
// steps: Igea 1.34e-5), a degree of normal snapping shows along its cells' borders (Igea's seam
// ratio 2.65 -> 2.79), and where a mesh has no normals its shading is the height gradient's
// (even 1/256 texel steps: the bust's close-up seam ratio 1.72 -> 1.79, bar 1.8).
inline constexpr double kPointHeightStep = 1.0 / 16, kMeshHeightStep = 0;
inline constexpr double kPointNormalTolerance = 1.5, kMeshNormalTolerance = 0;

// The widest --sparse-reach (PackOptions::sparseReach), in the pack's sample spacings.
inline constexpr double kMaxSparseReach = 16;

struct PackOptions {
  uint64_t memBudget = uint64_t(1) << 30;     // bytes
  uint64_t texelBudget = 0;       // at most this many texels over all tiles (0: kMaxTexelsPerPoint per point)
  double texelSize = 0;           // world units, every cell; 0 = per cell from its points' spacing
  double texelPerSpacing = 0.5;   // texel size as a fraction of the sample spacing
  double coverageRadius = 1.5;    // in sample spacings: texels whose surface point is farther stay empty
  // Point inputs: how far (in the pack's sample spacings, over kMaxScale = 1.5) a surface-like
  // sample's splat and coverage radii may follow its own spacing (--sparse-reach; 1.5: as far as
  // every other sample's, which leaves surfaces sampled much more sparsely than the pack as speckle).
  double sparseReach = 1.5;
  // --sparse-reach auto: the reach from the data (pipeline.cpp, autoSparseReach), in place of sparseReach.
  bool sparseReachAuto = false;
  // --sparse-reach was given (auto or a reach other than the default).
  bool sparseReachGiven() const { return sparseReachAuto || sparseReach != PackOptions{}.sparseReach; }
  double gapReach = 2;            // in coverage radii: gaps inside a tile whose every texel is this near surface close
  double splatRadius = 1.5;       // in sample spacings: the point splat kernel (tangent planes)
  double outlierRatio = 3;        // local outlier test of point inputs (0: keep every point)
  bool smooth = true;             // point inputs: moving-least-squares smoothing
  bool asPoints = false;          // ignore faces: pull-push from the vertices
  bool strict = false;            // NaN/Inf coordinates are an error instead of skipped
  bool force = false;             // repack even when the output is up to date
  bool reproducible = false;      // no timings in META: the same input and options give the same bytes
  bool compressPages = true;      // pages coded losslessly per tile (HGTZ, NRMZ, COLZ) instead of raw
  int pageLevel = kDefaultTileLevel;  // zstd level of the coded tiles (1..kMaxTileLevel)
  bool storeLevels = true;        // compressed pages: each tile's level 4 stored too (MIPZ)
  // What the pages keep (FORMAT.md, "Precision"): heights rounded to steps of at most this many
  // texels (0: every bit of the 16-bit code); normals and colours set to the page coder's
  // pyramid rebuild where that moves them by at most these degrees and grey levels (0: kept).
  // Negative: the defaults above for points or meshes (effectivePrecision).
  double heightStep = -1;
  double normalTolerance = -1;
  int colourTolerance = 4;
  Eigen::Vector3d up = Eigen::Vector3d::Zero();  // zero: from the format's convention or the data
  OctreeParams octree;
  int normalNeighbours = 24;
  uint32_t maxPageSize = 4096;
  std::string scratchParent;      // where chunk files go (default: beside the output)
  std::string commandLine;        // recorded in the NOTE section
};

// The precision a pack keeps: the options, with the defaults of a point or a mesh input.
struct Precision {
  double heightStep = 0, normalTolerance = 0;
  int colourTolerance = 0;
};
Precision effectivePrecision(const PackOptions& o, bool triangles);

struct PackSummary {
  uint64_t pointsRead = 0, pointsSkipped = 0, triangles = 0, outliersRemoved = 0, surfaceSamples = 0;
  uint32_t cells = 0, forcedCells = 0, degenerateCells = 0, layeredCells = 0, pages = 0, chunks = 0;
  uint32_t pageWidth = 0, pageHeight = 0;
  uint32_t chunksHeld = 0;  // chunks kept in memory instead of chunk files (DistributeOptions::inMemory)
  uint64_t texels = 0, fileBytes = 0;
  uint64_t scratchBytes = 0;     // written to temporary chunk files (compressed)
  uint64_t scratchRawBytes = 0;  // the same records uncompressed
  uint64_t codedScratchBytes = 0;  // coded tiles written to temporaries before the final file (compressed pages)
  double spacing = 0, areaSpacing = 0, texelSize = 0;  // texelSize: the median over cells
  double texelMin = 0, texelMax = 0;                     // the cells' finest and coarsest texels
  double seconds[6] = {0, 0, 0, 0, 0, 0};     // count, distribute, normals+octree, heightmaps, write, total
  double cpuSeconds[6] = {0, 0, 0, 0, 0, 0};  // the same phases' user + system seconds over all threads
  uint32_t ranks = 1;    // processes of a cluster pack (preprocess/cluster.h)
  uint32_t threads = 0;  // threads over all ranks
  std::vector<uint32_t> cellsPerLevel;
  bool normalsEstimated = false, fromTriangles = false, hasColor = false;
  Eigen::Vector3d up = Eigen::Vector3d::Zero();
  uint32_t upSource = 0;  // UpSource (atlas/pack_format.h)
  bool upToDate = false;  // the output already held this pack (same input hash): nothing done
  uint64_t inputHash = 0;
  double hashSeconds = 0;  // options, sizes, mesh files (the points are hashed as they are counted)
  // Point inputs: the --sparse-reach the pack used (the option's, or what auto chose), and the
  // share of the points that lie on surfaces sampled over kSpeckleScale pack spacings apart.
  double sparseReach = 0, sparseSurfaceShare = 0;
  std::vector<std::string> warnings;
};

// Point inputs get at most this many texels per point unless --texels says otherwise (a bound
// on bytes per point).
inline constexpr uint64_t kMaxTexelsPerPoint = 8;
// A point input's cell takes the texel of its own points' spacing, down to the pack's over this
// factor (pipeline.cpp, wantedTexels): a bound on what a few odd points can do to one tile.
inline constexpr double kLocalTexelRefine = 4;

// Bytes of working memory per point while a chunk is processed (records, positions,
// normals, neighbour grid, tile samples); sets the chunk size from the memory budget.
inline constexpr uint64_t kBytesPerPointInFlight = 240;
// Of the points the budget lets a chunk hold in memory, the share left for its halo (the
// neighbouring chunks' points near its faces, preprocess/chunk_halo.h): chunks take the rest,
// and a halo larger than its share is cut there.
inline constexpr uint64_t kHaloShareDiv = 5;  // a fifth
// The heightmaps phase: bytes a chunk holds per point while its tiles are made (record,
// position, normal, margin index), and a tile's working bytes at their peak per texel (the
// pull-push pyramid with colour and normal channels, surface, coverage, output and coded
// pages) and per sample. The tiles made at once are limited to the budget the chunk leaves.
inline constexpr uint64_t kChunkBytesPerPointInTiles = 96;
inline constexpr uint64_t kTileBytesPerTexel = 80;
inline constexpr uint64_t kTileBytesPerSample = 48;
// A point cell's most points under a memory budget: its tile's working bytes (at
// kMaxTexelsPerPoint texels a point, a quarter more for the tile's pad, and its samples with
// their margin) within a quarter of the budget, so that tiles fit beside their chunk.
inline uint32_t maxLeafPoints(uint64_t memBudget) {
  const uint64_t perPoint = kTileBytesPerTexel * kMaxTexelsPerPoint * 5 / 4 + kTileBytesPerSample * 4 / 3;
  return static_cast<uint32_t>(std::clamp<uint64_t>(memBudget / 4 / perPoint, 4096, UINT32_MAX));
}

Status packInput(const InputSet& input, const std::string& outPath, const PackOptions& options,
                 const ProgressFn& progress, PackSummary& summary);

}  // namespace sa
