#include "preprocess/pipeline.h"

#include <xxhash.h>
#include <sys/resource.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <mutex>
#include <numeric>
#include <optional>
#include <span>
#include <unordered_map>

#include "atlas/pack_file.h"
#include "atlas/packing.h"
#include "common/fileio.h"
#include "common/raw_vector.h"
#include "common/serial.h"
#include "preprocess/cell_margin.h"
#include "preprocess/chunk_halo.h"
#include "preprocess/cluster.h"
#include "preprocess/normals.h"
#include "preprocess/pullpush.h"
#include "preprocess/triangle_cells.h"
#include "preprocess/up_axis.h"

namespace sa {
namespace {

using Clock = std::chrono::steady_clock;


double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// User + system seconds of every thread of this process so far.
double processCpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

// A phase's wall and CPU seconds (PackSummary::seconds, cpuSeconds; their ratio is the cores
// it kept busy).
struct PhaseTimer {
  Clock::time_point wall = Clock::now();
  double cpu = processCpuSeconds();
  void stop(PackSummary& s, int phase) const {
    s.seconds[phase] = secondsSince(wall);
    s.cpuSeconds[phase] = processCpuSeconds() - cpu;
  }
};

Eigen::Vector3d vec(const double* d) { return Eigen::Vector3d(d[0], d[1], d[2]); }

// The most a point sample's radii grow with its local spacing, over the pack's (sampleScale).
// Past twice that, random samples' coverage disks (1.5 x 1.5 pack spacings) cover under about
// four fifths of their surface: it shows as specks.
constexpr float kMaxScale = 1.5f, kSpeckleScale = 2 * kMaxScale;

// A chunk's surface-like points (kChunkSurfaceLike) counted by their local spacing over the
// chunk's (ChunkPoint::spacing), in bins of an eighth of an octave from 3/8 to 48 (the last bin
// holds everything wider): what the sparse-surface warning and --sparse-reach auto read
// (sparseSurfaces). kSpeckleScale is a bin edge, so a pack of one chunk counts exactly.
constexpr int kReachBinsPerOctave = 8, kReachBins = 7 * kReachBinsPerOctave;
using ReachHistogram = std::array<uint64_t, kReachBins>;
constexpr double kReachBinFloor = kSpeckleScale / 8;  // the first bin's lower edge, in chunk spacings

struct WorkCell {
  CellRecord rec{};
  uint32_t chunk = 0, first = 0, count = 0;  // range of the chunk's points (cell order), surface samples included
  double ext[6] = {0, 0, 0, 0, 0, 0};        // point extents in the frame: uMin uMax vMin vMax wMin wMax
  bool sampled = false;                      // holds points sampled on large triangles
  float spacing = 0;  // point inputs: the median area spacing of its points (0: unknown, use the pack's)
  // Point inputs: the largest area spacing of its surface-like points (kChunkSurfaceLike), which
  // sets how far its tile and margin reach (cellReach).
  float surfaceSpacing = 0;
};

// Progress from inside one chunk's parallel loops: threads add the points they finished; the
// one that takes the lock reports (the others never wait), at most every 16384 points.
class ChunkTicker {
 public:
  // unitsPerPoint: what add() counts per point of the chunk.
  ChunkTicker(const ProgressFn& fn, const char* phase, uint64_t before, uint64_t chunk, uint64_t total,
              uint64_t unitsPerPoint = 1)
      : fn_(fn), phase_(phase), before_(before), chunk_(chunk), total_(total), per_(unitsPerPoint) {}
  void add(uint64_t n) {
    const uint64_t d = done_ += n;
    if (!fn_ || (d >> 14) == ((d - n) >> 14) || !mu_.try_lock()) return;
    fn_(phase_, before_ + std::min(d / per_, chunk_), total_);
    mu_.unlock();
  }

 private:
  const ProgressFn& fn_;
  const char* phase_;
  uint64_t before_, chunk_, total_, per_;
  std::atomic<uint64_t> done_{0};
  std::mutex mu_;
};

// What the phases of one pack share.
struct PackJob {
  PackJob(const InputSet& in, const PackOptions& o, const ProgressFn& p, PackSummary& s)
      : input(in), opt(o), progress(p), sum(s) {}
  const InputSet& input;
  const PackOptions& opt;
  const ProgressFn& progress;
  PackSummary& sum;
  bool triangles = false, fileNormals = false, color = false;
  BoundsInfo bounds;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  Eigen::Vector3d sheetSide = Eigen::Vector3d::Zero();  // NormalOrientation::sheetSide
  Quantizer qz;
  ScratchDir scratch;
  DistributeResult dist;
  std::vector<WorkCell> cells;
  std::vector<uint32_t> vertexCell;                         // triangle path: the cell of each vertex
  std::vector<std::pair<uint32_t, uint32_t>> sampleCells;   // triangle path: (triangle, cell) of its surface samples
  std::vector<std::pair<uint32_t, uint32_t>> triCells;      // triangle path: (triangle, cell) to rasterize, sorted
  std::vector<double> chunkSpacing;  // per chunk: its sample spacing (ChunkPoint::spacing is relative to it)
  std::vector<double> chunkAreaSpacing;  // per chunk: its area spacing (sizes pass B's neighbour grid)
  std::vector<ReachHistogram> chunkSurfaceSpacings;  // per chunk: ChunkCells::surfaceSpacings
  double sparseReach = 1.5;  // --sparse-reach, or what auto chose (resolveSparseReach)
  HeightMoments heights;             // of the input points, for the sign of a terrain's up axis
  double spacingSum = 0, areaSpacingSum = 0;
  uint64_t spacingWeight = 0;
  double texel = 0;        // the median of cellTexel
  std::vector<double> cellTexel;  // per cell: its texel (world units)
  double texelWanted = 0;  // the median texel the data asked for (before any cap)
  std::string texelCap;    // what coarsened it ("" = nothing)
  std::vector<CellRecord> records;
  PackMeta meta{};
  std::vector<int> owners;  // per chunk: the rank that processes it (chunkOwners)
  // Point inputs of more than one chunk: each chunk's neighbours' points near its cube, as
  // distributed for pass A and as fitted for pass B (preprocess/chunk_halo.h).
  HaloSet haloA, haloB;
  std::optional<ChunkLocator> chunkAt;  // which chunk holds a position (set with the halos)
  std::vector<Spacing> ownSpacing;  // per chunk this rank owns: its spacing, when writeHalosA had it
  uint64_t scratch0 = 0, raw0 = 0;  // chunk bytes this process had written before the pack
  double otherCpu = 0;              // cluster pack: the other ranks' CPU seconds
  uint64_t otherScratch[2] = {0, 0};  // and their chunk bytes (compressed, raw)
};

// pos is resized without zeroing (RawVector): its pages are first touched by the loop, on every core.
void decodePositions(std::span<const ChunkPoint> pts, const Quantizer& qz, RawVector<double>& pos) {
  pos.resize(pts.size() * 3);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pts.size(), 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i)
      for (int a = 0; a < 3; ++a) pos[3 * i + a] = qz.decode(pts[i].q[a], a);
  });
}

// Fills the summary from an existing pack (the up-to-date case).
void summarizeExisting(const PackReader& r, PackSummary& sum) {
  const PackMeta& m = r.meta();
  sum.pointsRead = m.sourcePoints;
  sum.pointsSkipped = m.skippedPoints;
  sum.outliersRemoved = m.outliersRemoved;
  sum.triangles = m.sourceTriangles;
  sum.cells = m.cellCount;
  sum.pages = m.pageCount;
  sum.pageWidth = m.pageWidth;
  sum.pageHeight = m.pageHeight;
  sum.chunks = m.chunkCount;
  sum.texels = m.texelsUsed;
  sum.spacing = m.sampleSpacing;
  sum.texelSize = m.texelSize;
  sum.fileBytes = r.fileBytes();
  sum.hasColor = r.hasColor();
  sum.up = r.up();
  sum.upSource = m.upSource;
  sum.fromTriangles = (m.flags & kPackFromTriangles) != 0;
  sum.normalsEstimated = (m.flags & kPackNormalsEstimated) != 0;
  for (const CellRecord& c : r.cells()) {
    if (c.level >= sum.cellsPerLevel.size()) sum.cellsPerLevel.resize(c.level + 1, 0);
    ++sum.cellsPerLevel[c.level];
    sum.forcedCells += (c.flags & kCellForced) != 0;
    sum.degenerateCells += (c.flags & kCellDegenerate) != 0;
  }
}

// ---- pass 1: bounds ----
// A cloud whose smallest extent (standard deviation) is under a tenth of the middle one is one
// open sheet: its estimated normals all take one side, the format's up side where the sheet
// faces it (a field, a floor), else the side of the normal's largest component (a wall). Away
// from the centroid would split a sheet into patches facing either way (its centroid lies in it).
Eigen::Vector3d sheetSide(const Eigen::Matrix3d& covariance, const InputSet& input) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(covariance);
  if (!(es.eigenvalues()(0) < 0.01 * es.eigenvalues()(1))) return Eigen::Vector3d::Zero();
  Eigen::Vector3d n = es.eigenvectors().col(0);
  const Eigen::Vector3d up = input.files().empty() ? Eigen::Vector3d::Zero() : input.files()[0].up;
  int big = 0;
  n.cwiseAbs().maxCoeff(&big);
  const double s = up.norm() > 0 && std::abs(n.dot(up.normalized())) > 0.3 ? n.dot(up) : n[big];
  return s < 0 ? Eigen::Vector3d(-n) : n;
}

Status boundsPhase(PackJob& job) {
  const PhaseTimer timer;
  SA_RETURN_IF_ERROR(computeBounds(job.input, job.bounds, job.progress, job.opt.strict, true));
  job.sum.pointsRead = job.bounds.count;
  job.sum.pointsSkipped = job.bounds.skipped;
  // Colour channels that never vary (a LAS file whose RGB fields are all 0) are no colour.
  job.color = job.input.anyHasColors() && job.bounds.colorVaries;
  if (job.input.anyHasColors() && !job.bounds.colorVaries)
    job.sum.warnings.push_back("every point has the same colour; the pack is shaded without colour");
  job.origin = (job.bounds.min + job.bounds.max) / 2;
  job.sheetSide = sheetSide(job.bounds.covariance, job.input);
  const Eigen::Vector3d ext = job.bounds.max - job.bounds.min;
  job.qz.cubeSize = std::max(ext.maxCoeff() * 1.0001, std::max(1e-12, 1e-12 * job.origin.cwiseAbs().maxCoeff()));
  job.qz.cubeMin = Eigen::Vector3d::Constant(-job.qz.cubeSize / 2);
  timer.stop(job.sum, 0);
  return Status::ok();
}

// ---- pass 2: distribute into chunks ----
Status distributePhase(PackJob& job, const std::string& outPath) {
  const PhaseTimer timer;
  // Leftovers of a killed pack (chunk directories, a partial output) are removed, not reused.
  const std::string scratchParent = job.opt.scratchParent.empty() ? directoryOf(outPath) : job.opt.scratchParent;
  removeStaleTemporaries(scratchParent, ".scanatlas-chunks-");
  removeStaleTemporaries(directoryOf(outPath), std::filesystem::path(outPath).filename().string() + ".tmp-");
  SA_RETURN_IF_ERROR(job.scratch.create(scratchParent, ".scanatlas-chunks-"));
  DistributeOptions dopt;
  dopt.maxPointsPerChunk = std::max<uint64_t>(1024, job.opt.memBudget / kBytesPerPointInFlight / kHaloShareDiv * (kHaloShareDiv - 1));
  dopt.scratchDir = job.scratch.path();
  dopt.origin = job.origin;
  dopt.keepTriangles = job.triangles;
  dopt.inMemory = !Cluster::distributed();
  SA_RETURN_IF_ERROR(distributePoints(job.input, job.qz, dopt, job.dist, job.progress));
  job.sum.triangles = job.dist.triangles;
  job.sum.surfaceSamples = job.dist.surfaceSamples;
  job.sum.chunks = static_cast<uint32_t>(job.dist.chunks.size());
  job.sum.chunksHeld = static_cast<uint32_t>(
      std::count_if(job.dist.chunks.begin(), job.dist.chunks.end(), [](const ChunkInfo& c) { return c.held != nullptr; }));
  timer.stop(job.sum, 1);
  if (job.triangles && job.dist.triangles == 0)
    return Status::badInput(job.input.files()[0].path + ": face element holds no triangles; use --as-points");
  if (job.triangles)
    SA_RETURN_IF_ERROR(vertexNormalCones(job.dist.trianglePath, job.dist.vertexPos, job.dist.vertexNormal, job.dist.vertexCone));
  return Status::ok();
}

// Normals of a chunk's points from the file or the mesh (zero where unknown), on every core.
void givenNormals(const PackJob& job, std::span<const ChunkPoint> pts, RawVector<float>& nrm) {
  nrm.resize(3 * pts.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pts.size(), 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      float* out = &nrm[3 * i];
      std::fill(out, out + 3, 0.f);
      if (job.fileNormals || (pts[i].flags & kChunkSurfaceSample)) {
        std::copy(pts[i].n, pts[i].n + 3, out);
      } else if (job.triangles) {
        const size_t v = pts[i].vid;
        if (3 * v + 2 < job.dist.vertexNormal.size()) {
          Eigen::Vector3f nn(&job.dist.vertexNormal[3 * v]);
          if (nn.norm() > 0) nn.normalize();
          std::copy(nn.data(), nn.data() + 3, out);
        }
      }
    }
  });
}

// The fit's output laid out in its grid order (pos, nrm, keep: the point at i was at order[i] in
// the file's order, where pts still is): pts laid out too, the outliers (keep 0) dropped from all
// three. Returns where each kept point now is, in the file's order of the kept points: the
// octree's first index array. The octree then splits the points exactly as it did over the
// file's order, and its sums add the same numbers in the same order, while it and the chunk's
// rewrite, which visit the points by cell, read nearby memory.
// Its arrays are made without zeroing (RawVector): the loops that fill them touch them first.
std::vector<uint32_t> layOutKept(ChunkRecords& pts, RawVector<double>& pos, RawVector<float>& nrm,
                                 const std::vector<uint8_t>& keep, const std::vector<uint32_t>& order) {
  const size_t n = pts.size();
  RawVector<uint32_t> rank(n);  // a kept point's index among the kept, in the file's order
  RawVector<uint8_t> kept(n);  // every entry written below: order is a permutation
  const tbb::blocked_range<size_t> all(0, n, 1 << 14);
  tbb::parallel_for(all, [&](const tbb::blocked_range<size_t>& b) {
    for (size_t i = b.begin(); i != b.end(); ++i) kept[order[i]] = keep[i];
  });
  uint32_t r = 0;
  for (size_t o = 0; o < n; ++o) rank[o] = kept[o] ? r++ : 0;
  RawVector<uint32_t> to(n);  // where a kept point goes in the grid's order
  uint32_t m = 0;
  for (size_t i = 0; i < n; ++i) {
    to[i] = m;
    m += keep[i];
  }
  std::vector<uint32_t> place(r);
  ChunkRecords laid(r);
  tbb::parallel_for(all, [&](const tbb::blocked_range<size_t>& b) {  // the records, gathered on every core
    for (size_t i = b.begin(); i != b.end(); ++i)
      if (keep[i]) {
        place[rank[order[i]]] = to[i];
        laid[to[i]] = pts[order[i]];
      }
  });
  for (size_t i = 0; i < n; ++i)  // in place: a kept point moves down only
    if (keep[i] && to[i] != i) {
      std::copy_n(&pos[3 * i], 3, &pos[3 * size_t(to[i])]);
      std::copy_n(&nrm[3 * i], 3, &nrm[3 * size_t(to[i])]);
    }
  pts = std::move(laid);
  pos.resize(3 * size_t(r));
  nrm.resize(3 * size_t(r));
  return place;
}

// Point inputs: outliers out, normals, moving-least-squares smoothing (preprocess/normals.h),
// pts, pos and nrm laid out in the fit's grid order (SurfaceOptions::layOut) and the outliers
// dropped from them: returns where each kept point went (layOutKept).
// Points from own on are the chunk's halo: neighbours in the fit, then dropped like outliers
// (and not counted as such).
std::vector<uint32_t> fitChunkSurface(const PackJob& job, ChunkRecords& pts, RawVector<double>& pos,
                                      RawVector<float>& nrm, const Spacing& spacing, ChunkTicker& ticker,
                                      uint64_t& removed, size_t own) {
  const double chunkSpacing = spacing.nearest;
  NormalOrientation orient;
  orient.towardScanner = job.input.towardScanner();
  orient.center = job.bounds.centroid - job.origin;
  orient.sheetSide = job.sheetSide;
  orient.scan = pts.empty() ? nullptr : &pts[0].scan;
  orient.scanStride = sizeof(ChunkPoint);
  SurfaceOptions so;
  so.neighbours = job.opt.normalNeighbours;
  so.estimateNormals = !job.fileNormals;
  so.smooth = job.opt.smooth;
  so.outlierRatio = job.opt.outlierRatio;
  so.spacing = spacing.area > 0 ? spacing.area : spacing.nearest;
  so.progress = [&](size_t n) { ticker.add(n); };
  std::vector<uint8_t> keep;
  RawVector<float> local(pts.size());  // every entry written by the fit
  std::vector<uint8_t> surface(pts.size(), 0);
  std::vector<uint32_t> order;
  so.layOut = true;
  so.neighboursFrom = own;
  so.surfaceLike = surface.data();
  removed = fitSurface(pos.data(), pts.size(), orient, so, nrm.data(), keep, local.data(), &order);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pts.size(), 1 << 14), [&](const tbb::blocked_range<size_t>& b) {
    for (size_t i = b.begin(); i != b.end(); ++i) {
      ChunkPoint& p = pts[order[i]];
      p.spacing = chunkSpacing > 0 ? uint16_t(std::clamp(std::lround(local[i] / chunkSpacing * 1024), 0L, 65535L)) : 0;
      p.flags = uint8_t((p.flags & ~kChunkSurfaceLike) | (surface[i] ? kChunkSurfaceLike : 0));
    }
  });
  return layOutKept(pts, pos, nrm, keep, order);
}

// Sample spacing of a chunk's input points (points sampled on large triangles left out).
Spacing chunkSpacing(std::span<const ChunkPoint> pts, std::span<const double> pos) {
  const bool sampled = std::any_of(pts.begin(), pts.end(), [](const ChunkPoint& p) { return p.flags & kChunkSurfaceSample; });
  if (!sampled) return estimateSpacing(pos.data(), pts.size());
  std::vector<double> real;
  for (size_t i = 0; i < pts.size(); ++i)
    if (!(pts[i].flags & kChunkSurfaceSample)) real.insert(real.end(), &pos[3 * i], &pos[3 * i] + 3);
  return estimateSpacing(real.data(), real.size() / 3);
}

// What pass A found in one chunk, before it joins the job (mergeChunkCells): computed by the
// rank that owns the chunk, merged in chunk order by every rank, so a cluster pack and a lone
// process make the same cells. Cell ids are the chunk's own (0 = its first cell).
struct ChunkCells {
  std::vector<WorkCell> cells;
  std::vector<std::pair<uint32_t, uint32_t>> samples;      // (triangle, cell) of surface samples
  std::vector<std::pair<uint32_t, uint32_t>> vertexCells;  // (vertex, cell), triangle path
  HeightMoments heights;
  double spacing = 0, areaSpacing = 0;  // the chunk's sample spacings
  uint64_t weight = 0;                  // points the spacings stand for
  uint64_t count = 0, outliers = 0;     // points kept, points dropped as outliers
  uint32_t layered = 0;
  ReachHistogram surfaceSpacings{};     // its surface-like points by spacing (kReachBins)

  void write(ByteWriter& w) const {
    w.put(cells);
    w.put(samples);
    w.put(vertexCells);
    for (const Eigen::Vector3d* v : {&heights.sum, &heights.sum2, &heights.sum3}) w.put(std::array<double, 3>{v->x(), v->y(), v->z()});
    w.put(heights.count);
    w.put(std::array<double, 2>{spacing, areaSpacing});
    w.put(std::array<uint64_t, 3>{weight, count, outliers});
    w.put(layered);
    w.put(surfaceSpacings);
  }
  void read(ByteReader& r) {
    r.get(cells);
    r.get(samples);
    r.get(vertexCells);
    for (Eigen::Vector3d* v : {&heights.sum, &heights.sum2, &heights.sum3}) {
      std::array<double, 3> a;
      r.get(a);
      *v = Eigen::Vector3d(a[0], a[1], a[2]);
    }
    r.get(heights.count);
    std::array<double, 2> sp;
    r.get(sp);
    spacing = sp[0];
    areaSpacing = sp[1];
    std::array<uint64_t, 3> n;
    r.get(n);
    weight = n[0];
    count = n[1];
    outliers = n[2];
    r.get(layered);
    r.get(surfaceSpacings);
  }
};

// The median local area spacing (ChunkPoint::spacing, relative to the chunk's spacing) of the
// input points in sorted[first, first + count); 0 when none is known (meshes, surface samples).
float medianSpacing(std::span<const ChunkPoint> sorted, uint32_t first, uint32_t count, double chunkSpacing) {
  std::vector<uint16_t> s;
  s.reserve(count);
  for (uint32_t k = first; k < first + count; ++k)
    if (sorted[k].spacing && !(sorted[k].flags & kChunkSurfaceSample)) s.push_back(sorted[k].spacing);
  if (s.empty() || !(chunkSpacing > 0)) return 0.f;
  std::nth_element(s.begin(), s.begin() + long(s.size() / 2), s.end());
  return float(s[s.size() / 2] * chunkSpacing / 1024);
}

// The in-plane axes of a cell's tile: the plane fit's, or one of the cube's axes projected onto
// the plane (v = w x u), whichever bounds the points in the smallest rectangle. The fit of a
// flat patch has no preferred direction in its plane, and a tile turned 45 degrees from its
// cube's footprint spends about half its texels outside it.
void tileAxes(const OctreeCell& c, const std::vector<uint32_t>& idx, std::span<const double> pos, PlaneFit& f) {
  if (f.degenerate || c.count < 3) return;
  Eigen::Vector3d us[4] = {f.u}, vs[4] = {f.v};
  int n = 1;
  for (int a = 0; a < 3; ++a) {
    const Eigen::Vector3d p = Eigen::Vector3d::Unit(a) - f.w[a] * f.w;
    if (p.norm() < 0.5) continue;  // the axis is within 30 degrees of the normal
    us[n] = p.normalized();
    vs[n] = f.w.cross(us[n]);
    ++n;
  }
  double lo[4][2], hi[4][2];
  for (int k = 0; k < n; ++k) lo[k][0] = lo[k][1] = 1e300, hi[k][0] = hi[k][1] = -1e300;
  for (uint32_t i = c.first; i < c.first + c.count; ++i) {
    const Eigen::Vector3d d = vec(&pos[3 * size_t(idx[i])]) - f.centroid;
    for (int k = 0; k < n; ++k) {
      const double x = d.dot(us[k]), y = d.dot(vs[k]);
      lo[k][0] = std::min(lo[k][0], x), hi[k][0] = std::max(hi[k][0], x);
      lo[k][1] = std::min(lo[k][1], y), hi[k][1] = std::max(hi[k][1], y);
    }
  }
  int best = 0;
  auto area = [&](int k) { return (hi[k][0] - lo[k][0]) * (hi[k][1] - lo[k][1]); };
  for (int k = 1; k < n; ++k)
    if (area(k) < 0.95 * area(best)) best = k;  // the fit's own axes unless clearly larger
  f.u = us[best];
  f.v = vs[best];
}

// One of the octree's cells of chunk ci: its frame, its extent in that frame, its points.
WorkCell workCell(uint32_t ci, const OctreeCell& c, const std::vector<uint32_t>& idx, std::span<const double> pos,
                  std::span<const ChunkPoint> sorted, double chunkSpacing) {
  WorkCell wc;
  wc.chunk = ci;
  wc.first = c.first;
  wc.count = c.count;
  PlaneFit f = c.fit;
  tileAxes(c, idx, pos, f);
  for (int a = 0; a < 3; ++a) {
    wc.rec.origin[a] = f.centroid[a];
    wc.rec.u[a] = f.u[a];
    wc.rec.v[a] = f.v[a];
    wc.rec.w[a] = f.w[a];
  }
  wc.rec.level = static_cast<uint8_t>(std::min(c.level, 255));
  wc.rec.flags = (c.forced ? kCellForced : 0) | (f.degenerate ? kCellDegenerate : 0);
  double e[6] = {1e300, -1e300, 1e300, -1e300, 1e300, -1e300};
  uint32_t real = 0;
  for (uint32_t k = c.first; k < c.first + c.count; ++k) {
    const Eigen::Vector3d d = vec(&pos[3 * size_t(idx[k])]) - f.centroid;
    const double uvw[3] = {d.dot(f.u), d.dot(f.v), d.dot(f.w)};
    for (int a = 0; a < 3; ++a) {
      e[2 * a] = std::min(e[2 * a], uvw[a]);
      e[2 * a + 1] = std::max(e[2 * a + 1], uvw[a]);
    }
    if (sorted[k].flags & kChunkSurfaceSample) wc.sampled = true;
    else ++real;
    if (sorted[k].flags & kChunkSurfaceLike)
      wc.surfaceSpacing = std::max(wc.surfaceSpacing, float(sorted[k].spacing * chunkSpacing / 1024));
  }
  wc.rec.pointCount = real;
  wc.spacing = medianSpacing(sorted, c.first, c.count, chunkSpacing);
  std::copy(e, e + 6, wc.ext);
  return wc;
}

// Records the octree's cells of a chunk (frames, extents, which vertices and samples they hold):
// the cells on every core, then the lists of samples and vertices in cell order.
void addCells(bool triangles, uint32_t ci, const std::vector<OctreeCell>& oc, const std::vector<uint32_t>& idx,
              std::span<const double> pos, std::span<const ChunkPoint> sorted, ChunkCells& out) {
  const size_t base = out.cells.size();
  out.cells.resize(base + oc.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, oc.size(), 16), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t k = r.begin(); k != r.end(); ++k) out.cells[base + k] = workCell(ci, oc[k], idx, pos, sorted, out.spacing);
  });
  for (size_t k = 0; k < oc.size(); ++k) {
    const OctreeCell& c = oc[k];
    const uint32_t cellId = static_cast<uint32_t>(base + k);
    out.layered += c.fit.layered;
    for (uint32_t i = c.first; i < c.first + c.count; ++i) {
      if (sorted[i].flags & kChunkSurfaceSample) out.samples.emplace_back(sorted[i].vid, cellId);
      else if (triangles) out.vertexCells.emplace_back(sorted[i].vid, cellId);
    }
  }
}

// The chunk's surface-like input points by their spacing over the chunk's (ChunkCells::surfaceSpacings).
ReachHistogram surfaceSpacings(std::span<const ChunkPoint> sorted) {
  // Bin b holds the spacings (x 1024) in [edge[b], edge[b + 1]).
  static const std::array<uint32_t, kReachBins> edge = [] {
    std::array<uint32_t, kReachBins> e{};
    for (int b = 0; b < kReachBins; ++b)
      e[size_t(b)] = uint32_t(std::ceil(kReachBinFloor * 1024 * std::exp2(double(b) / kReachBinsPerOctave)));
    return e;
  }();
  ReachHistogram h{};
  for (const ChunkPoint& p : sorted) {
    if (!(p.flags & kChunkSurfaceLike) || (p.flags & kChunkSurfaceSample) || p.spacing < edge[0]) continue;
    ++h[size_t(std::upper_bound(edge.begin(), edge.end(), uint32_t(p.spacing)) - edge.begin() - 1)];
  }
  return h;
}

// Chunk ci's cells join the job: ids after the cells of the chunks before it.
void mergeChunkCells(PackJob& job, uint32_t ci, const ChunkCells& c) {
  const uint32_t base = static_cast<uint32_t>(job.cells.size());
  job.cells.insert(job.cells.end(), c.cells.begin(), c.cells.end());
  for (const auto& [tri, cell] : c.samples) job.sampleCells.emplace_back(tri, base + cell);
  for (const auto& [v, cell] : c.vertexCells) job.vertexCell[v] = base + cell;
  job.heights.sum += c.heights.sum;
  job.heights.sum2 += c.heights.sum2;
  job.heights.sum3 += c.heights.sum3;
  job.heights.count += c.heights.count;
  if (c.spacing > 0) {
    job.spacingSum += c.spacing * double(c.weight);
    job.areaSpacingSum += c.areaSpacing * double(c.weight);
    job.spacingWeight += c.weight;
  }
  job.chunkSpacing[ci] = c.spacing;
  job.chunkAreaSpacing[ci] = c.areaSpacing;
  job.chunkSurfaceSpacings[ci] = c.surfaceSpacings;
  job.dist.chunks[ci].count = c.count;
  job.sum.outliersRemoved += c.outliers;
  job.sum.layeredCells += c.layered;
}

// Positions pass B reads of a point input keep 1/2^kChunkPositionBits of the chunk's sample
// spacing (texels are about a spacing wide).
constexpr int kChunkPositionBits = 10;

// Rounds a point chunk's positions to multiples of the largest power-of-two step of the
// quantizer's grid under spacing / 2^kChunkPositionBits, so that the low bits the chunk files
// would otherwise carry as noise are zero (the frames shift them out).
void roundChunkPositions(const Quantizer& qz, double spacing, std::span<double> pos) {
  if (!(spacing > 0)) return;
  const double unit = qz.cubeSize / 4294967296.0;
  const int bits = std::clamp(int(std::floor(std::log2(std::ldexp(spacing, -kChunkPositionBits) / unit))), 0, 24);
  if (bits == 0) return;
  const uint32_t half = 1u << (bits - 1), mask = ~((1u << bits) - 1);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pos.size(), 3 << 14), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      const uint32_t q = qz.encode(pos[i], int(i % 3));
      const uint32_t rounded = q >= mask ? (q & mask) : ((q + half) & mask);
      pos[i] = qz.decode(rounded, int(i % 3));
    }
  });
}

// How far past its cube a chunk's halo reaches, in the source chunk's area spacings: a point's
// 24 nearest neighbours (pass A's fit) lie within about 2.8; pass B's tiles reach the coverage
// radius (1.5 spacings) past their cells' points and their normal field 2.25 past that. (At 6,
// the 2 M-point survey's halos held 28 % of its points in 17 chunks; at 4, 20 %.)
constexpr double kHaloSpacings = 4;

// The most halo points a chunk takes: its share of the memory budget (kHaloShareDiv).
size_t haloLimit(const PackJob& job) { return std::max<uint64_t>(1024, job.opt.memBudget / kBytesPerPointInFlight / kHaloShareDiv); }

// The halo's fragments this rank wrote, made known to every rank.
void shareHalo(HaloSet& h) {
  if (Cluster::distributed()) mergeHaloSources(h, Cluster::allGather(haloSources(h)));
}

// ---- pass A, one chunk: normals (+ smoothing, outliers), the octree, the chunk rewritten in cell order ----
Status chunkCells(const PackJob& job, uint32_t ci, const ProgressFn& progress, uint64_t before, uint64_t total,
                  HaloSet& haloB, ChunkCells& out) {
  const ChunkInfo& ch = job.dist.chunks[ci];
  ChunkRecords pts;
  RawVector<double> pos;
  RawVector<float> nrm;
  SA_RETURN_IF_ERROR(loadChunk(ch, pts));
  const size_t own = pts.size();  // then the halo
  SA_RETURN_IF_ERROR(takeHalo(job.haloA, ci, pts, haloLimit(job)));
  decodePositions(pts, job.qz, pos);
  givenNormals(job, pts, nrm);
  for (size_t i = 0; i < own; ++i)
    if (!(pts[i].flags & kChunkSurfaceSample)) out.heights.add(Eigen::Vector3d(&pos[3 * i]));
  const bool known = ci < job.ownSpacing.size() && (job.ownSpacing[ci].area > 0 || job.ownSpacing[ci].nearest > 0);
  const Spacing spacing = known ? job.ownSpacing[ci]
                                : chunkSpacing(std::span<const ChunkPoint>(pts.data(), own), std::span<const double>(pos.data(), 3 * own));
  const double sp = spacing.nearest;
  out.spacing = sp;
  out.areaSpacing = std::max(spacing.area, sp);
  out.weight = own;
  ChunkTicker ticker(progress, "octree", before, own, total, 2);
  std::vector<uint32_t> idx;
  if (!job.triangles) {
    idx = fitChunkSurface(job, pts, pos, nrm, spacing, ticker, out.outliers, own);
  } else {
    idx.resize(pts.size());
    for (uint32_t i = 0; i < idx.size(); ++i) idx[i] = i;
  }
  const size_t n = pts.size();
  Eigen::Vector3d cmin;
  double csize;
  nodeCube(job.qz, ch.level, ch.ix, ch.iy, ch.iz, cmin, csize);
  OctreeParams op = job.opt.octree;
  op.maxDepth = std::max(op.maxDepth, ch.level);
  if (op.outlierFraction < 0) op.outlierFraction = job.triangles ? 0.0 : kPointOutlierFraction;
  if (op.minSplitPoints == 0) op.minSplitPoints = job.triangles ? kMeshMinSplit : kPointMinSplit;
  if (op.maxLeafPoints == 0 && !job.triangles) op.maxLeafPoints = maxLeafPoints(job.opt.memBudget);
  if (sp > 0 && op.layerGap == 0) {
    // Layers farther apart than twice the coverage radius would leave the surface between
    // them uncovered: such a cell is not one height field.
    op.layerBin = 2 * sp;
    op.layerGap = 2 * job.opt.coverageRadius * sp;
  }
  std::vector<float> cone;  // mesh vertices: the test holds for every face around them
  if (job.triangles) {
    cone.assign(n, 0.f);
    for (size_t i = 0; i < n; ++i)
      if (!(pts[i].flags & kChunkSurfaceSample) && pts[i].vid < job.dist.vertexCone.size()) cone[i] = job.dist.vertexCone[pts[i].vid];
  }
  std::vector<OctreeCell> oc;
  buildOctree(pos.data(), nrm.data(), idx, cmin, csize, ch.level, op, oc, cone.empty() ? nullptr : cone.data());
  // Rewrite the chunk in cell order with its normals and (smoothed) positions, for pass B. A point
  // input's pass B needs neither the point's index in its file nor its scan: zeroed, their planes
  // of the byte-shuffled frames compress to nothing (the triangle path keeps both). Normals are
  // rounded to multiples of 2^-kChunkNormalBits (under 0.002 degree; the pack keeps 10 bits):
  // their low mantissa bytes become zero and compress to nothing too.
  // A point input's positions are rounded first (roundChunkPositions), so that the cells' extents
  // hold what pass B reads.
  if (!job.triangles) roundChunkPositions(job.qz, sp, pos);
  ChunkRecords sorted(n);  // not zeroed: the loop below touches its pages first, on every core
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      const size_t s = idx[i];
      sorted[i] = pts[s];
      for (int a = 0; a < 3; ++a) sorted[i].n[a] = roundToChunkNormal(nrm[3 * s + a]);
      for (int a = 0; a < 3; ++a) sorted[i].q[a] = job.qz.encode(pos[3 * s + a], a);
      if (!job.triangles) sorted[i].vid = sorted[i].scan = 0;
    }
  });
  out.count = n;
  addCells(job.triangles, ci, oc, idx, pos, sorted, out);
  if (!job.triangles) out.surfaceSpacings = surfaceSpacings(sorted);
  if (!haloB.from.empty())
    SA_RETURN_IF_ERROR(writeHalo(haloB, job.qz, job.dist.chunks, *job.chunkAt, ci, sorted, kHaloSpacings * out.areaSpacing));
  return saveChunk(ch, std::move(sorted));
}

// ---- the ranks of a cluster pack (preprocess/cluster.h) ----
// The rank that processes each chunk in passes A and B: the largest chunks first, each to the
// least loaded rank (one rank: every chunk is rank 0's).
std::vector<int> chunkOwners(const std::vector<ChunkInfo>& chunks, int ranks) {
  std::vector<uint32_t> order(chunks.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return chunks[a].count > chunks[b].count; });
  std::vector<uint64_t> load(std::max(1, ranks), 0);
  std::vector<int> owner(chunks.size(), 0);
  for (uint32_t ci : order) {
    const int r = static_cast<int>(std::min_element(load.begin(), load.end()) - load.begin());
    owner[ci] = r;
    load[r] += chunks[ci].count;
  }
  return owner;
}

// Points of the chunks this rank owns (before outliers are dropped).
uint64_t pointsOwned(const PackJob& job) {
  uint64_t n = 0;
  for (size_t ci = 0; ci < job.dist.chunks.size(); ++ci)
    if (job.owners[ci] == Cluster::rank()) n += job.dist.chunks[ci].count;
  return n;
}

// A rank sees only its own chunks' progress: reported as the whole job's (rank 0 prints it).
ProgressFn shareProgress(const ProgressFn& p, uint64_t mine, uint64_t total) {
  if (!p || mine == total) return p;
  return [p, mine, total](const char* phase, uint64_t done, uint64_t) {
    p(phase, mine ? static_cast<uint64_t>(double(done) / double(mine) * double(total)) : total, total);
  };
}

// Every rank's ChunkCells (chunk index, then the record, for each chunk it owns) merged by every
// rank in chunk order.
void mergeRanksCells(PackJob& job, const std::vector<uint8_t>& mine) {
  std::vector<ChunkCells> byChunk(job.dist.chunks.size());
  for (const std::vector<uint8_t>& bytes : Cluster::allGather(mine)) {
    ByteReader r(bytes);
    while (!r.done()) {
      uint32_t ci = 0;
      r.get(ci);
      SA_CHECK(ci < byChunk.size());
      byChunk[ci].read(r);
    }
  }
  for (uint32_t ci = 0; ci < byChunk.size(); ++ci) mergeChunkCells(job, ci, byChunk[ci]);
}

// Before pass A: every chunk this rank owns writes its points near the other chunks' cubes, as
// distributed (pass A rewrites the chunk files). Point inputs of more than one chunk only.
// `progress` and `mine` are the cells phase's (this rank's points).
Status writeHalosA(PackJob& job, const ProgressFn& progress, uint64_t mine) {
  const std::vector<ChunkInfo>& chunks = job.dist.chunks;
  if (job.triangles || chunks.size() < 2) return Status::ok();
  const std::string dir = std::filesystem::path(chunks[0].path).parent_path().string();
  job.haloA = HaloSet{dir, "a", {}};
  job.haloB = HaloSet{dir, "b", {}};
  job.haloA.from.resize(chunks.size());
  job.haloB.from.resize(chunks.size());
  job.ownSpacing.assign(chunks.size(), Spacing{});
  job.chunkAt.emplace(chunks);
  // Progress: the points of this rank's chunks read so far (an extra read of the chunk files).
  uint64_t done = 0;
  if (progress) progress("halos", 0, mine);
  Status s;
  for (uint32_t ci = 0; ci < chunks.size() && s; ++ci) {
    if (job.owners[ci] != Cluster::rank()) continue;
    if (progress) progress("halos", done, mine);
    done += chunks[ci].count;
    ChunkRecords pts;
    RawVector<double> pos;
    s = loadChunk(chunks[ci], pts);
    if (!s) break;
    decodePositions(pts, job.qz, pos);
    const Spacing sp = job.ownSpacing[ci] = chunkSpacing(pts, pos);  // kept for pass A
    s = writeHalo(job.haloA, job.qz, chunks, *job.chunkAt, ci, pts, kHaloSpacings * std::max(sp.area, sp.nearest));
  }
  if (progress && s) progress("halos", mine, mine);
  SA_RETURN_IF_ERROR(Cluster::agree(s));
  shareHalo(job.haloA);
  return Status::ok();
}

Status cellsPhase(PackJob& job) {
  const PhaseTimer timer;
  if (job.triangles) job.vertexCell.assign(job.dist.vertexPos.size() / 3, UINT32_MAX);
  job.chunkSpacing.assign(job.dist.chunks.size(), 0.0);
  job.chunkAreaSpacing.assign(job.dist.chunks.size(), 0.0);
  job.chunkSurfaceSpacings.assign(job.dist.chunks.size(), ReachHistogram{});
  job.owners = chunkOwners(job.dist.chunks, Cluster::size());
  if (job.dist.chunks.size() < size_t(Cluster::size()))
    job.sum.warnings.push_back(std::to_string(job.dist.chunks.size()) + " chunk(s) for " + std::to_string(Cluster::size()) +
                               " MPI ranks: ranks without a chunk wait (a smaller --mem-budget makes more chunks)");
  const uint64_t total = job.bounds.count + job.dist.surfaceSamples, mine = pointsOwned(job);
  const ProgressFn progress = shareProgress(job.progress, mine, total);
  Status s = writeHalosA(job, progress, mine);
  if (progress) progress("octree", 0, mine);
  uint64_t processed = 0;
  ByteWriter shared;  // cluster pack: this rank's chunks' cells, for the others
  for (uint32_t ci = 0; ci < job.dist.chunks.size() && s; ++ci) {
    if (job.owners[ci] != Cluster::rank()) continue;
    const uint64_t count = job.dist.chunks[ci].count;  // before outliers are dropped
    ChunkCells cells;
    s = chunkCells(job, ci, progress, processed, mine, job.haloB, cells);
    processed += count;
    if (progress) progress("octree", processed, mine);
    if (!Cluster::distributed()) {
      mergeChunkCells(job, ci, cells);
    } else {
      shared.put(ci);
      cells.write(shared);
    }
  }
  SA_RETURN_IF_ERROR(Cluster::agree(s));
  if (Cluster::distributed()) mergeRanksCells(job, shared.bytes());
  shareHalo(job.haloB);
  std::sort(job.sampleCells.begin(), job.sampleCells.end());
  job.sampleCells.erase(std::unique(job.sampleCells.begin(), job.sampleCells.end()), job.sampleCells.end());
  timer.stop(job.sum, 2);
  job.sum.spacing = job.spacingWeight ? job.spacingSum / double(job.spacingWeight) : job.qz.cubeSize * 1e-3;
  if (!(job.sum.spacing > 0)) job.sum.spacing = job.qz.cubeSize * 1e-3;
  job.sum.areaSpacing = job.spacingWeight ? job.areaSpacingSum / double(job.spacingWeight) : job.sum.spacing;
  if (job.cells.empty()) return Status::badInput(job.input.files()[0].path + ": no cells produced");
  if (job.cells.size() > 16u << 20) return Status::badInput("more than 16 Mi cells; lower --max-depth");
  return Status::ok();
}

// ---- texel size, tiles, atlas layout ----
// A point sample's splat and coverage radii are the options' (in the pack's spacings) times its
// local spacing over the pack's, at least 1 and at most kMaxScale: enough that a region seen by
// one scan of several (twice the merged spacing) is not peppered with holes, while sparse loose
// returns (vegetation), water and a scan's edges do not grow blobs of surface where no point is.
// With --sparse-reach R a surface-like sample (kChunkSurfaceLike: its neighbours lie on a
// smooth surface) follows its spacing up to R, so that a surface sampled more sparsely than the
// pack (a terrestrial scan's far field, a strip flown higher) is covered as dense ones are.
float sampleScale(double sparseReach, const ChunkPoint& p, double toPack) {
  const float s = float(p.spacing * toPack);
  return std::clamp(s, 1.f, (p.flags & kChunkSurfaceLike) ? std::max(kMaxScale, float(sparseReach)) : kMaxScale);
}

// How far a point cell's tile and margin reach past its points, over the coverage radius: a
// sample at kMaxScale or less reaches past the tile's edge into the neighbours' margins as it
// always did; a cell of sparser surface-like samples reaches as far as its widest one's radius.
double cellReach(const PackJob& job, const WorkCell& c) {
  const double s = std::min(c.surfaceSpacing / job.sum.spacing, job.sparseReach);
  return std::max(1.0, s / kMaxScale);
}

// How far a cell's tile reaches past its points' extents at texel t. Point tiles: the coverage
// radius. Triangle tiles hold their triangles whole (assignPhase grew the extents) plus a texel,
// and cells holding points sampled on large triangles reach the lattice step past those points.
double tilePad(const PackJob& job, const WorkCell& c, double t) {
  if (!job.triangles) return job.opt.coverageRadius * job.sum.spacing * cellReach(job, c);
  return std::max(t, c.sampled ? job.dist.surfaceSampleStep : 0.0);
}

// The texel each cell's data asks for. Point inputs: from the area each of the cell's own points
// stands for (the median over the cell; the nearest-neighbour spacing underestimates where
// samples come in lines), down to 1/kLocalTexelRefine of the pack's, so a survey's dense
// overlaps and a scan's near side keep their detail. Never coarser than the pack's: edges and
// height jumps are placed to a texel, and coarser texels in sparse cells drew surface away from
// the points (autzen: pixels over 3 spacings from any point 0.5 -> 1.9 %). Meshes (from the
// vertex spacing) and --texel-size: one texel for every cell.
std::vector<double> wantedTexels(const PackJob& job) {
  const PackOptions& opt = job.opt;
  const double pack = opt.texelSize > 0 ? opt.texelSize
                                        : (job.triangles ? job.sum.spacing : job.sum.areaSpacing) * opt.texelPerSpacing;
  std::vector<double> t(job.cells.size(), pack);
  if (opt.texelSize > 0 || job.triangles) return t;
  for (size_t i = 0; i < t.size(); ++i)
    if (job.cells[i].spacing > 0)
      t[i] = std::clamp(double(job.cells[i].spacing) * opt.texelPerSpacing, pack / kLocalTexelRefine, pack);
  return t;
}

// The most texels a pack may have: --texels when given; otherwise kMaxTexelsPerPoint per input
// point (meshes: per vertex and surface sample, and at least 64 Mi), a bound on bytes per point
// that the data's own spacing meets unless samples are very unevenly spread.
uint64_t texelCap(const PackJob& job) {
  if (job.opt.texelBudget) return job.opt.texelBudget;
  const uint64_t samples = job.bounds.count + (job.triangles ? job.dist.surfaceSamples : 0);
  return std::max<uint64_t>(job.triangles ? uint64_t(64) << 20 : 4096, kMaxTexelsPerPoint * samples);
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// Tile sizes at texels `scale` x `wanted`; returns the texels over all tiles.
uint64_t tileSizes(const PackJob& job, const std::vector<double>& wanted, double scale, std::vector<TileSize>& sizes) {
  const uint32_t maxTile = job.opt.maxPageSize - 2;
  uint64_t texels = 0;
  sizes.resize(job.cells.size());
  for (size_t i = 0; i < job.cells.size(); ++i) {
    const WorkCell& c = job.cells[i];
    const double t = scale * wanted[i], pad = tilePad(job, c, t);
    const double eu = c.ext[1] - c.ext[0] + 2 * pad, ev = c.ext[3] - c.ext[2] + 2 * pad;
    sizes[i].w = static_cast<uint32_t>(std::clamp(std::ceil(eu / t), 1.0, double(maxTile)));
    sizes[i].h = static_cast<uint32_t>(std::clamp(std::ceil(ev / t), 1.0, double(maxTile)));
    texels += uint64_t(sizes[i].w) * sizes[i].h;
  }
  return texels;
}

// Per cell its texel (job.cellTexel) and tile size: the wanted texels, all coarsened by one
// factor where the cap (texelCap) asks for it, and what coarsened them recorded and reported.
std::vector<TileSize> chooseTexels(PackJob& job) {
  PackSummary& sum = job.sum;
  const PackOptions& opt = job.opt;
  const std::vector<double> wanted = wantedTexels(job);
  const uint64_t cap = texelCap(job);
  double area = 0;
  for (size_t i = 0; i < job.cells.size(); ++i) {
    const WorkCell& c = job.cells[i];
    const double t = wanted[i], pad = tilePad(job, c, t);
    area += (c.ext[1] - c.ext[0] + 2 * pad + t) * (c.ext[3] - c.ext[2] + 2 * pad + t) / (t * t);
  }
  double scale = opt.texelSize > 0 ? 1.0 : std::max(1.0, std::sqrt(area / double(cap)));
  std::vector<TileSize> sizes;
  for (int iter = 0; iter < 40; ++iter) {
    sum.texels = tileSizes(job, wanted, scale, sizes);
    if (sum.texels <= cap || opt.texelSize > 0) break;
    scale *= std::sqrt(double(sum.texels) / double(cap)) * 1.01;
  }
  job.cellTexel.resize(wanted.size());
  for (size_t i = 0; i < wanted.size(); ++i) job.cellTexel[i] = scale * wanted[i];
  const auto [lo, hi] = std::minmax_element(job.cellTexel.begin(), job.cellTexel.end());
  sum.texelMin = lo == job.cellTexel.end() ? 0 : *lo;
  sum.texelMax = hi == job.cellTexel.end() ? 0 : *hi;
  sum.texelSize = job.texel = median(job.cellTexel);
  job.texelWanted = median(wanted);
  if (scale > 1.05) {
    char msg[96];
    if (opt.texelBudget) std::snprintf(msg, sizeof msg, "--texels %llu", (unsigned long long)cap);
    else std::snprintf(msg, sizeof msg, "%llu texels per point", (unsigned long long)kMaxTexelsPerPoint);
    job.texelCap = msg;
    char warn[256];
    std::snprintf(warn, sizeof warn,
                  "the texel cap (%s) made texels %.2fx coarser than the data's (median %.4g instead of %.4g): "
                  "detail is lost%s",
                  msg, scale, job.texel, job.texelWanted, opt.texelBudget ? "; raise --texels" : "; --texels N allows more");
    sum.warnings.push_back(warn);
  }
  return sizes;
}

// The points on surfaces sampled at least kSpeckleScale of the pack's spacings apart: the
// surface-like points (ChunkCells::surfaceSpacings) of the bins whose lower edge is that far in the
// pack's spacings, their share of the points, and what --sparse-reach auto chooses for them.
struct SparseSurfaces {
  uint64_t points = 0;
  double share = 0;
  // Their median spacing in the pack's spacings (log-linear within its bin), within [kMaxScale,
  // kMaxSparseReach]; kMaxScale when there are none. The median rather than a higher quantile:
  // the widest of a random scatter's local spacings are its gaps, which the fit's neighbours and
  // gap closing bridge anyway (the test sheet's sparse half, 16x fewer points per area: median
  // 7.3, IoU 0.989; 6 gave 0.987; its 90th percentile is about 9).
  double reach = kMaxScale;
};
SparseSurfaces sparseSurfaces(const PackJob& job) {
  SparseSurfaces out;
  std::vector<std::pair<double, uint64_t>> q;  // (bin's lower edge in pack spacings, points)
  for (size_t ci = 0; ci < job.chunkSurfaceSpacings.size(); ++ci) {
    const double toPack = kReachBinFloor * job.chunkSpacing[ci] / job.sum.spacing;
    for (int b = 0; b < kReachBins; ++b) {
      const uint64_t n = job.chunkSurfaceSpacings[ci][size_t(b)];
      const double lower = toPack * std::exp2(double(b) / kReachBinsPerOctave);
      if (n == 0 || !(lower >= kSpeckleScale * (1 - 1e-9))) continue;
      q.emplace_back(lower, n);
      out.points += n;
    }
  }
  uint64_t points = 0;
  for (const WorkCell& c : job.cells) points += c.rec.pointCount;
  if (out.points == 0 || points == 0) return out;
  out.share = double(out.points) / double(points);
  std::sort(q.begin(), q.end());
  uint64_t below = 0;
  size_t k = 0;
  for (; 2 * (below + q[k].second) < out.points; ++k) below += q[k].second;
  const double into = (0.5 * double(out.points) - double(below)) / double(q[k].second);  // of bin k, in [0, 1]
  out.reach = std::clamp(q[k].first * std::exp2(into / kReachBinsPerOctave), double(kMaxScale), kMaxSparseReach);
  return out;
}

// The --sparse-reach this pack uses (the option's, or what auto chooses), and the warning when
// over 1 % of the points lie on surfaces that the default draws as speckle.
void resolveSparseReach(PackJob& job) {
  const bool given = job.opt.sparseReachGiven();
  if (job.triangles) {
    job.sparseReach = job.opt.sparseReach;
    if (given) job.sum.warnings.push_back("--sparse-reach does nothing here: mesh faces are rasterized (it is for point inputs)");
    return;
  }
  const SparseSurfaces sp = sparseSurfaces(job);
  job.sparseReach = job.sum.sparseReach = job.opt.sparseReachAuto ? sp.reach : job.opt.sparseReach;
  job.sum.sparseSurfaceShare = sp.share;
  if (given && !job.opt.smooth && job.fileNormals)
    job.sum.warnings.push_back("--sparse-reach does nothing here: the surface test is the smoothing fit's, which "
                               "--no-smooth skips on files with normals");
  if (job.opt.sparseReachAuto || job.opt.sparseReach > kMaxScale || sp.share <= 0.01) return;
  char warn[320];
  std::snprintf(warn, sizeof warn,
                "%.1f %% of the points lie on surfaces sampled over %.0f sample spacings apart (a scan's far field, "
                "water, a strip flown higher): they show as scattered specks; --sparse-reach auto (here %.1f) draws "
                "them as surface",
                100 * sp.share, double(kSpeckleScale), sp.reach);
  job.sum.warnings.push_back(warn);
}

void layoutPhase(PackJob& job) {
  PackSummary& sum = job.sum;
  const PackOptions& opt = job.opt;
  resolveSparseReach(job);
  const std::vector<TileSize> sizes = chooseTexels(job);
  const PackingResult layout = packAtlas(sizes, opt.maxPageSize);
  job.records.resize(job.cells.size());
  for (size_t i = 0; i < job.cells.size(); ++i) {
    WorkCell& c = job.cells[i];
    CellRecord& r = c.rec;
    const double t = job.cellTexel[i], pad = tilePad(job, c, t);
    const double eu = c.ext[1] - c.ext[0] + 2 * pad, ev = c.ext[3] - c.ext[2] + 2 * pad;
    // The tile spans the box exactly: widen the box to whole texels, centred on the points.
    const double su = std::max(sizes[i].w * t, eu), sv = std::max(sizes[i].h * t, ev);
    const double cu = (c.ext[0] + c.ext[1]) / 2, cv = (c.ext[2] + c.ext[3]) / 2;
    const double wpad = std::max(0.5 * t, 1e-9 * job.qz.cubeSize);
    r.box[0] = cu - su / 2;
    r.box[1] = cu + su / 2;
    r.box[2] = cv - sv / 2;
    r.box[3] = cv + sv / 2;
    r.box[4] = c.ext[4] - wpad;
    r.box[5] = c.ext[5] + wpad;
    r.page = layout.placements[i].page;
    r.tileX = layout.placements[i].x;
    r.tileY = layout.placements[i].y;
    r.tileW = static_cast<uint16_t>(sizes[i].w);
    r.tileH = static_cast<uint16_t>(sizes[i].h);
    job.records[i] = r;
    if (r.level >= sum.cellsPerLevel.size()) sum.cellsPerLevel.resize(r.level + 1, 0);
    ++sum.cellsPerLevel[r.level];
    if (r.flags & kCellForced) ++sum.forcedCells;
    if (r.flags & kCellDegenerate) ++sum.degenerateCells;
  }
  sum.cells = static_cast<uint32_t>(job.cells.size());
  sum.pages = layout.pageCount;
  sum.pageWidth = layout.pageWidth;
  sum.pageHeight = layout.pageHeight;
}

// ---- the up axis: given, the format's convention, or from the data (preprocess/up_axis.h) ----
void upPhase(PackJob& job) {
  std::vector<UpCell> cells(job.cells.size());
  for (size_t i = 0; i < job.cells.size(); ++i) {
    cells[i].w = vec(job.cells[i].rec.w);
    const double* e = job.cells[i].ext;
    cells[i].area = (e[1] - e[0]) * (e[3] - e[2]);
  }
  const UpDecision d = decideUp(job.input, job.opt.up, job.bounds.min, job.bounds.max, cells, job.heights,
                                job.fileNormals || job.triangles);
  job.sum.up = d.up;
  job.sum.upSource = d.source;
}

PackMeta makeMeta(const PackJob& job) {
  const PackSummary& sum = job.sum;
  PackMeta meta{};
  for (int a = 0; a < 3; ++a) {
    meta.origin[a] = job.origin[a];
    meta.boundsMin[a] = job.bounds.min[a] - job.origin[a];
    meta.boundsMax[a] = job.bounds.max[a] - job.origin[a];
    meta.up[a] = sum.up[a];
  }
  meta.upSource = sum.upSource;
  meta.texelSize = job.texel;
  meta.sampleSpacing = sum.spacing;
  meta.sourcePoints = job.bounds.count;
  meta.skippedPoints = job.bounds.skipped;
  meta.outliersRemoved = sum.outliersRemoved;
  meta.sourceTriangles = job.dist.triangles;
  meta.pageWidth = sum.pageWidth;
  meta.pageHeight = sum.pageHeight;
  meta.pageCount = sum.pages;
  meta.flags = (job.color && !job.triangles ? uint32_t(kPackHasColor) : 0u) |
               (job.triangles ? uint32_t(kPackFromTriangles) : 0u) |
               (sum.normalsEstimated ? uint32_t(kPackNormalsEstimated) : 0u) | uint32_t(kPackHasNormals);
  meta.maxDepth = static_cast<uint32_t>(job.opt.octree.maxDepth);
  meta.chunkCount = sum.chunks;
  meta.texelsUsed = sum.texels;
  meta.inputHash = sum.inputHash;
  return meta;
}

}  // namespace

Precision effectivePrecision(const PackOptions& o, bool triangles) {
  Precision p;
  p.heightStep = o.heightStep >= 0 ? o.heightStep : triangles ? kMeshHeightStep : kPointHeightStep;
  p.normalTolerance = o.normalTolerance >= 0 ? o.normalTolerance : triangles ? kMeshNormalTolerance : kPointNormalTolerance;
  p.colourTolerance = std::max(0, o.colourTolerance);
  return p;
}

namespace {

// NOTE (FORMAT.md): one "source: <path>" line per input, then the command line.
std::string makeNote(const PackJob& job) {
  std::string note;
  for (const auto& f : job.input.sourcePaths()) note += "source: " + f + "\n";
  for (const auto& f : job.input.files())
    if (!f.columns.empty()) {
      note += "columns: " + f.columns + "\n";
      break;
    }
  note += "command: " + job.opt.commandLine + "\n";
  char texel[160];
  std::snprintf(texel, sizeof texel, "texel: %.9g wanted %.9g%s%s\n", job.texel, job.texelWanted,
                job.texelCap.empty() ? "" : " capped by ", job.texelCap.c_str());
  note += texel;
  char precision[160];
  const Precision p = effectivePrecision(job.opt, job.triangles);
  std::snprintf(precision, sizeof precision, "precision: height-step %.9g normal-tolerance %.9g colour-tolerance %d\n",
                p.heightStep, p.normalTolerance, p.colourTolerance);
  note += precision;
  if (!job.triangles && job.opt.sparseReachGiven()) {  // only when given
    char reach[96];
    std::snprintf(reach, sizeof reach, "sparse-reach: %.9g%s\n", job.sparseReach, job.opt.sparseReachAuto ? " auto" : "");
    note += reach;
  }
  return note;
}

// Triangle path: which cells rasterize each triangle (preprocess/triangle_cells.h); cells'
// extents grow to hold their triangles whole.
Status assignPhase(PackJob& job) {
  std::vector<CellExtent> ext(job.cells.size());
  for (size_t i = 0; i < job.cells.size(); ++i) {
    const CellRecord& r = job.cells[i].rec;
    ext[i] = {vec(r.origin), vec(r.u), vec(r.v), vec(r.w), {}};
    std::copy(job.cells[i].ext, job.cells[i].ext + 6, ext[i].ext);
  }
  TriangleCellInput in;
  in.vertexPos = &job.dist.vertexPos;
  in.vertexCell = &job.vertexCell;
  in.sampleCells = &job.sampleCells;
  in.trianglePath = job.dist.trianglePath;
  in.minCos = std::cos(job.opt.octree.maxAngleDeg * M_PI / 180);
  SA_RETURN_IF_ERROR(assignTrianglesToCells(in, ext, job.triCells));
  for (size_t i = 0; i < job.cells.size(); ++i) std::copy(ext[i].ext, ext[i].ext + 6, job.cells[i].ext);
  return Status::ok();
}

// Triangle path: the triangles of chunk ci's cells, as vertex-index triples per cell.
Status chunkTriangles(const PackJob& job, uint32_t ci, std::unordered_map<uint32_t, std::vector<uint32_t>>& cellTris) {
  std::FILE* f = std::fopen(job.dist.trianglePath.c_str(), "rb");
  if (!f) return Status::internal(job.dist.trianglePath + ": cannot reopen");
  std::vector<uint32_t> buf(3 * 65536);
  size_t got;
  uint32_t triIndex = 0;
  auto tc = job.triCells.begin();
  while ((got = std::fread(buf.data(), 12, buf.size() / 3, f)) > 0) {
    for (size_t k = 0; k < got; ++k, ++triIndex) {
      for (; tc != job.triCells.end() && tc->first == triIndex; ++tc) {
        if (job.cells[tc->second].chunk != ci) continue;
        auto& list = cellTris[tc->second];
        list.insert(list.end(), &buf[3 * k], &buf[3 * k] + 3);
      }
    }
  }
  std::fclose(f);
  return Status::ok();
}

// One cell's tile from its triangles: the box's height range grows to hold the whole of every
// triangle touching the cell (within the padding), so the parts of those triangles outside the
// cell's own vertices are not cut where the neighbouring box does not reach either.
void triangleTile(const PackJob& job, const std::vector<uint32_t>* tris, CellRecord& r, PackWriter& writer,
                  uint32_t id, TileGrid& g, TileOutput& tile) {
  const Eigen::Vector3d O = vec(r.origin), U = vec(r.u), V = vec(r.v), Wn = vec(r.w);
  std::vector<double> tri;
  std::vector<float> normals;
  if (tris)
    for (uint32_t vi : *tris) {
      const Eigen::Vector3d d = vec(&job.dist.vertexPos[3 * size_t(vi)]) - O;
      tri.insert(tri.end(), {d.dot(U), d.dot(V), d.dot(Wn)});
      Eigen::Vector3f n = 3 * size_t(vi) + 2 < job.dist.vertexNormal.size() ? Eigen::Vector3f(&job.dist.vertexNormal[3 * size_t(vi)])
                                                                           : Eigen::Vector3f::Zero();
      if (n.norm() > 0) n.normalize();
      normals.insert(normals.end(), {n.x(), n.y(), n.z()});
    }
  double wLo = r.box[4], wHi = r.box[5];
  const double reach = std::max(r.box[1] - r.box[0], r.box[3] - r.box[2]);
  for (size_t k = 2; k < tri.size(); k += 3) {
    wLo = std::min(wLo, std::max(tri[k], r.box[4] - reach));
    wHi = std::max(wHi, std::min(tri[k], r.box[5] + reach));
  }
  r.box[4] = g.wMin = wLo;
  r.box[5] = g.wMax = wHi;
  writer.setCellHeights(id, wLo, wHi);
  rasterizeTile(g, tri.data(), tri.size() / 9, 0.5 * job.texel, std::cos(job.opt.octree.maxAngleDeg * M_PI / 180),
                normals.data(), tile);
}

// The tile's stored normals from the chunk's normal field (MarginFinder::normalField) at each
// covered texel's surface point: neighbouring cells then store the same normal where their
// tiles overlap. Splatted from the tile's own samples, a cell's normals near its border would
// average a one-sided neighbourhood, several degrees off its neighbour's on a curved surface.
constexpr double kFieldScale = 1.5;  // the field's radius over the splat radius

void fieldNormals(const CellRecord& r, const TileGrid& g, const MarginFinder& margins, double radius, TileOutput& tile) {
  const Eigen::Vector3d O = vec(r.origin), U = vec(r.u), V = vec(r.v), Wn = vec(r.w);
  MarginFinder::TileTexels t(tile.heights.size());
  for (size_t k = 0; k < tile.heights.size(); ++k) {
    if (!tile.heights[k]) continue;
    const int i = static_cast<int>(k % size_t(g.width)), j = static_cast<int>(k / size_t(g.width));
    const double h = decodeHeight(tile.heights[k], tile.wMin, tile.wMax);
    const Eigen::Vector3d x = O + U * (g.u0 + (i + 0.5) * g.du) + V * (g.v0 + (j + 0.5) * g.dv) + Wn * h;
    double n[3];
    decodeNormal(&tile.normals[kNormalBytes * k], n);
    t.x[k] = x.x(), t.y[k] = x.y(), t.z[k] = x.z();
    t.hx[k] = float(n[0]), t.hy[k] = float(n[1]), t.hz[k] = float(n[2]);
  }
  margins.tileField({O, U, V, g.u0, g.v0, g.du, g.dv, g.width, g.height}, radius, t);
  for (size_t k = 0; k < tile.heights.size(); ++k)
    if (tile.heights[k]) encodeNormal(t.hx[k], t.hy[k], t.hz[k], &tile.normals[kNormalBytes * k]);
}

// Past its own points (in the margin the neighbours' samples fill), a cell keeps only texels
// that face it: where the surface turns steep in its frame, a texel spans a long stretch of
// surface and its height and normal are poor, while the neighbouring cell that owns those
// points sees them face-on. Kept, such texels win the depth test by noise and show as seams.
constexpr double kMarginMinCos = 0.5;

void dropSteepMargin(const WorkCell& c, const TileGrid& g, TileOutput& tile) {
  double frame[3];
  for (size_t t = 0; t < tile.heights.size(); ++t) {
    if (!tile.heights[t]) continue;
    const int i = static_cast<int>(t % size_t(g.width)), j = static_cast<int>(t / size_t(g.width));
    const double u = g.u0 + (i + 0.5) * g.du, v = g.v0 + (j + 0.5) * g.dv;
    if (u >= c.ext[0] && u <= c.ext[1] && v >= c.ext[2] && v <= c.ext[3]) continue;
    decodeNormal(&tile.normals[kNormalBytes * t], frame);
    const double nw = frame[0] * g.frame[6] + frame[1] * g.frame[7] + frame[2] * g.frame[8];
    if (nw < kMarginMinCos) {
      tile.heights[t] = 0;
      --tile.covered;
    }
  }
}

// One cell's tile from its points (in the rewritten chunk: smoothed, with normals) and the
// neighbouring cells' points in its margin (preprocess/cell_margin.h).
void pointTile(const PackJob& job, const WorkCell& c, CellRecord& r, std::span<const ChunkPoint> pts,
               std::span<const double> pos, const MarginFinder& margins, bool withColor, PackWriter& writer,
               uint32_t id, TileGrid& g, TileOutput& tile) {
  const Eigen::Vector3d O = vec(r.origin), U = vec(r.u), V = vec(r.v), Wn = vec(r.w);
  const double cover = job.opt.coverageRadius * job.sum.spacing;
  std::vector<uint32_t> idx(c.count);
  for (uint32_t k = 0; k < c.count; ++k) idx[k] = c.first + k;
  MarginFinder::Cell mc{O, U, V, Wn, {}, c.first, c.count};
  std::copy(c.ext, c.ext + 6, mc.ext);
  margins.find(mc, cover * cellReach(job, c), std::cos(job.opt.octree.maxAngleDeg * M_PI / 180), idx);
  const size_t n = idx.size();
  std::vector<double> u(n), v(n), w(n);
  std::vector<float> nf(3 * n);
  std::vector<uint8_t> rgb(withColor ? 3 * n : 0);
  std::vector<float> scale(n);
  const double toPack = job.chunkSpacing[c.chunk] / 1024 / job.sum.spacing;
  double wLo = r.box[4], wHi = r.box[5];
  for (size_t k = 0; k < n; ++k) {
    const size_t pi = idx[k];
    const Eigen::Vector3d d = vec(&pos[3 * pi]) - O;
    u[k] = d.dot(U);
    v[k] = d.dot(V);
    w[k] = d.dot(Wn);
    wLo = std::min(wLo, w[k]);
    wHi = std::max(wHi, w[k]);
    const Eigen::Vector3d nn(pts[pi].n[0], pts[pi].n[1], pts[pi].n[2]);
    nf[3 * k] = float(nn.dot(U));
    nf[3 * k + 1] = float(nn.dot(V));
    nf[3 * k + 2] = float(nn.dot(Wn));
    if (withColor) std::copy(pts[pi].rgb, pts[pi].rgb + 3, &rgb[3 * k]);
    scale[k] = sampleScale(job.sparseReach, pts[pi], toPack);
  }
  g.wMin = wLo;
  g.wMax = wHi;
  TileSamples s;
  s.u = u.data();
  s.v = v.data();
  s.w = w.data();
  s.normal = nf.data();
  s.rgb = withColor ? rgb.data() : nullptr;
  s.scale = scale.data();
  s.n = n;
  SplatOptions so;
  so.splatRadius = job.opt.splatRadius * job.sum.spacing;
  so.coverageRadius = cover;
  so.gapReach = job.opt.gapReach * cover * cellReach(job, c);
  // The margin's samples and the surface between them may lie a little above or below the
  // cell's own points: the height range grows to hold them.
  so.fitHeightRange = true;
  pullPushTile(g, s, so, tile);
  r.box[4] = tile.wMin;
  r.box[5] = tile.wMax;
  writer.setCellHeights(id, tile.wMin, tile.wMax);
  fieldNormals(r, g, margins, job.opt.splatRadius * job.sum.spacing * kFieldScale, tile);
  dropSteepMargin(c, g, tile);
}

// The precision the options keep (PackOptions::heightStep and the tolerances): what the page
// coder then stores in fewer bytes.
void reducePrecision(const Precision& p, const TileGrid& g, TileOutput& tile) {
  tile.normalPyramid.clear();
  tile.rgbaPyramid.clear();
  if (p.heightStep > 0) roundHeights(tile, p.heightStep * std::min(g.du, g.dv));
  if (p.normalTolerance > 0) snapNormals(tile, g.width, g.height, p.normalTolerance);
  if (p.colourTolerance > 0) snapColours(tile, g.width, g.height, p.colourTolerance);
}

// Bytes shared by threads that each take some before their work and give them back after: a
// thread waits while what the others hold and what it asks for exceed the limit, unless it
// would be alone (a single larger piece of work still runs, by itself).
class ByteGate {
 public:
  explicit ByteGate(uint64_t limit) : limit_(limit) {}
  void take(uint64_t bytes) {
    std::unique_lock<std::mutex> lock(mu_);
    free_.wait(lock, [&] { return held_ == 0 || held_ + bytes <= limit_; });
    held_ += bytes;
  }
  void give(uint64_t bytes) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      held_ -= bytes;
    }
    free_.notify_all();
  }
  // Bytes held for one piece of work: given back when it ends, by an exception too (a thread
  // that never gave them back would leave the others waiting for ever).
  class Held {
   public:
    Held(ByteGate& gate, uint64_t bytes) : gate_(gate), bytes_(bytes) { gate_.take(bytes_); }
    ~Held() { gate_.give(bytes_); }
    Held(const Held&) = delete;
    Held& operator=(const Held&) = delete;

   private:
    ByteGate& gate_;
    const uint64_t bytes_;
  };

 private:
  std::mutex mu_;
  std::condition_variable free_;
  uint64_t held_ = 0;
  const uint64_t limit_;
};

// A tile's working bytes at their peak (kTileBytesPerTexel, kTileBytesPerSample; a point
// cell's samples include its margin, about a third more).
uint64_t tileBytes(const PackJob& job, uint32_t id) {
  const CellRecord& r = job.records[id];
  const uint64_t samples = job.triangles ? 0 : job.cells[id].count + job.cells[id].count / 3;
  return uint64_t(r.tileW) * r.tileH * kTileBytesPerTexel + samples * kTileBytesPerSample;
}

// What --mem-budget leaves for tiles while a chunk of `points` is loaded (at least a quarter).
uint64_t tileBudget(const PackJob& job, size_t points) {
  const uint64_t chunk = uint64_t(points) * kChunkBytesPerPointInTiles;
  return std::max(job.opt.memBudget / 4, job.opt.memBudget > chunk ? job.opt.memBudget - chunk : 0);
}

// The texel grid of a cell's tile: its box and frame.
TileGrid tileGrid(const CellRecord& r) {
  TileGrid g;
  g.width = r.tileW;
  g.height = r.tileH;
  g.u0 = r.box[0];
  g.v0 = r.box[2];
  g.du = (r.box[1] - r.box[0]) / r.tileW;
  g.dv = (r.box[3] - r.box[2]) / r.tileH;
  g.wMin = r.box[4];
  g.wMax = r.box[5];
  for (int a = 0; a < 3; ++a) {
    g.frame[a] = r.u[a];
    g.frame[3 + a] = r.v[a];
    g.frame[6 + a] = r.w[a];
  }
  return g;
}

// ---- pass B, one chunk: every cell's tile ----
Status chunkTiles(PackJob& job, uint32_t ci, const std::vector<uint32_t>& mine, PackWriter& writer, ChunkTicker& ticker) {
  ChunkRecords pts;
  RawVector<double> pos;
  SA_RETURN_IF_ERROR(loadChunk(job.dist.chunks[ci], pts));
  // The halo's points serve the cells' margins and normal field; their local spacings are
  // relative to their own chunk's spacing, made relative to this one's.
  SA_RETURN_IF_ERROR(takeHalo(job.haloB, ci, pts, haloLimit(job), [&](uint32_t source, std::span<ChunkPoint> h) {
    const double f = job.chunkSpacing[ci] > 0 ? job.chunkSpacing[source] / job.chunkSpacing[ci] : 0;
    for (ChunkPoint& p : h) p.spacing = uint16_t(std::clamp(std::lround(p.spacing * f), 0L, 65535L));
  }));
  decodePositions(pts, job.qz, pos);
  std::unordered_map<uint32_t, std::vector<uint32_t>> cellTris;
  if (job.triangles) SA_RETURN_IF_ERROR(chunkTriangles(job, ci, cellTris));
  const bool withColor = (job.meta.flags & kPackHasColor) != 0;
  RawVector<float> nrm(job.triangles ? 0 : 3 * pts.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, nrm.size() / 3, 1 << 14), [&](const tbb::blocked_range<size_t>& b) {
    for (size_t i = b.begin(); i != b.end(); ++i) std::copy(pts[i].n, pts[i].n + 3, &nrm[3 * i]);
  });
  const MarginFinder margins(pos.data(), nrm.data(), job.triangles ? 0 : pts.size(), job.chunkAreaSpacing[ci]);
  Status failed;
  std::mutex failMu;
  const Precision precision = effectivePrecision(job.opt, job.triangles);
  ByteGate gate(tileBudget(job, pts.size()));
  // One cell's tile made and written; its working memory is gone when it returns.
  auto makeTile = [&](uint32_t id) {
    CellRecord& r = job.records[id];
    TileGrid g = tileGrid(r);
    TileOutput tile;
    if (job.triangles) {
      auto it = cellTris.find(id);
      triangleTile(job, it == cellTris.end() ? nullptr : &it->second, r, writer, id, g, tile);
    } else {
      pointTile(job, job.cells[id], r, pts, pos, margins, withColor, writer, id, g, tile);
    }
    reducePrecision(precision, g, tile);
    return writer.writeTile(id, tile.heights.data(), tile.normals.empty() ? nullptr : tile.normals.data(),
                            withColor ? tile.rgba.data() : nullptr, tile.normalPyramid,
                            withColor ? std::span<const uint8_t>(tile.rgbaPyramid) : std::span<const uint8_t>{});
  };
  tbb::parallel_for(tbb::blocked_range<size_t>(0, mine.size(), 1), [&](const tbb::blocked_range<size_t>& rr) {
    for (size_t m = rr.begin(); m < rr.end(); ++m) {
      const uint32_t id = mine[m];
      Status s;
      {
        const ByteGate::Held held(gate, tileBytes(job, id));
        s = makeTile(id);
      }
      ticker.add(job.cells[id].count);
      if (!s) {
        std::lock_guard<std::mutex> lock(failMu);
        failed = s;
      }
    }
  });
  return failed;
}

Status tilesPhase(PackJob& job, PackWriter& writer) {
  std::vector<std::vector<uint32_t>> chunkCellIds(job.dist.chunks.size());
  for (uint32_t i = 0; i < job.cells.size(); ++i) chunkCellIds[job.cells[i].chunk].push_back(i);
  const uint64_t total = job.bounds.count + job.dist.surfaceSamples, mine = pointsOwned(job);
  const ProgressFn progress = shareProgress(job.progress, mine, total);
  uint64_t processed = 0;
  if (progress) progress("heightmaps", 0, mine);
  Status s;
  for (uint32_t ci = 0; ci < job.dist.chunks.size() && s; ++ci) {
    if (job.owners[ci] != Cluster::rank()) continue;
    ChunkTicker ticker(progress, "heightmaps", processed, job.dist.chunks[ci].count, mine);
    s = chunkTiles(job, ci, chunkCellIds[ci], writer, ticker);
    processed += job.dist.chunks[ci].count;
    // The chunks hold the points left after outlier removal: the last one ends the phase.
    if (progress) progress("heightmaps", ci + 1 == job.dist.chunks.size() ? mine : processed, mine);
  }
  return s;
}

// What a rank of a cluster pack tells rank 0 after its tiles: the height ranges its tiles
// widened, and for the summary its CPU seconds, chunk bytes and threads.
struct RankReport {
  std::vector<uint32_t> ids;
  std::vector<std::array<double, 2>> heights;
  std::string codedPath;                         // compressed pages: the rank's coded tiles
  std::vector<PackWriter::CellBlobs> coded;      // per id: where in codedPath
  std::array<double, 3> cpu{};      // normals + octree, heightmaps, the whole run
  std::array<uint64_t, 4> stats{};  // chunk bytes, their raw bytes, threads, coded tile bytes
  template <class IO>
  void io(IO& b) {
    b.io(ids);
    b.io(heights);
    b.io(codedPath);
    b.io(coded);
    b.io(cpu);
    b.io(stats);
  }
};

// Cluster pack, after every rank's tiles: rank 0's writer learns the others' cells' height
// ranges (their texels are in the file already) and the summary their work.
Status joinTiles(PackJob& job, PackWriter& writer, Status s) {
  if (!Cluster::distributed()) return s;
  if (Cluster::rank() != 0 && s) s = writer.leave();
  SA_RETURN_IF_ERROR(Cluster::agree(s));
  RankReport mine;
  for (uint32_t i = 0; i < job.cells.size(); ++i)
    if (job.owners[job.cells[i].chunk] == Cluster::rank()) {
      mine.ids.push_back(i);
      mine.heights.push_back({writer.cell(i).box[4], writer.cell(i).box[5]});
      if (job.opt.compressPages) mine.coded.push_back(writer.blobs(i));
    }
  mine.codedPath = writer.tempPath();
  mine.cpu = {job.sum.cpuSeconds[2], job.sum.cpuSeconds[3], processCpuSeconds()};
  mine.stats = {chunkBytesWritten() - job.scratch0, chunkRecordBytesWritten() - job.raw0, uint64_t(Cluster::threads()),
                writer.codedBytes()};
  ByteWriter w;
  mine.io(w);
  const std::vector<std::vector<uint8_t>> all = Cluster::allGather(w.bytes());
  job.sum.ranks = static_cast<uint32_t>(all.size());
  for (size_t rank = 1; rank < all.size(); ++rank) {
    RankReport other;
    ByteReader r(all[rank]);
    other.io(r);
    for (size_t k = 0; k < other.ids.size(); ++k) writer.setCellHeights(other.ids[k], other.heights[k][0], other.heights[k][1]);
    if (job.opt.compressPages) writer.adoptBlobs(other.codedPath, other.ids, other.coded);
    job.sum.cpuSeconds[2] += other.cpu[0];
    job.sum.cpuSeconds[3] += other.cpu[1];
    job.otherCpu += other.cpu[2];
    job.otherScratch[0] += other.stats[0];
    job.otherScratch[1] += other.stats[1];
    job.sum.threads += static_cast<uint32_t>(other.stats[2]);
    job.sum.codedScratchBytes += other.stats[3];
  }
  return Status::ok();
}

}  // namespace

// The input hash (PackMeta::inputHash) before the points: options, every file's size and
// transform, mesh files whole.
static Result<uint64_t> hashSetup(const InputSet& input, const PackOptions& o) {
  XXH3_state_t* st = XXH3_createState();
  XXH3_64bits_reset(st);
  char opts[768];
  // kPipelineRevision changes whenever packing changes what it writes for the same input, so
  // packs made by an older build are not mistaken for up to date.
  constexpr int kPipelineRevision = 15;  // 15: stored levels carry 4 x 4 coverage masks; 14: point packs' stored levels cover 0.4 of a footprint; 13: small gaps inside a tile closed; 12: stored coarser levels (MIPZ); 11: point chunks rounded to 1/1024 of their spacing for pass B; 10: point cells split past maxLeafPoints, chunk normals rounded to 15 bits; 9: precision options; 8: texels per cell from its spacing; 4: vertex-cone test, 16-bit normals, up-axis sign; 5: cracks; 6: normal signs propagated; 7: height moments summed per chunk
  const int n = std::snprintf(
      opts, sizeof(opts), "r%d f%u %llu %llu %.17g %.17g %.17g %.17g %.17g %d %d %.17g %.17g %.17g %d %u %.17g %.17g %d %u %d %.17g %.17g %d %d %d %.17g",
      kPipelineRevision, kPackVersion, (unsigned long long)o.memBudget, (unsigned long long)o.texelBudget, o.texelSize,
      o.texelPerSpacing, o.coverageRadius, o.splatRadius, o.outlierRatio, int(o.smooth), int(o.asPoints), o.up.x(),
      o.up.y(), o.up.z(), o.octree.maxDepth, o.octree.minSplitPoints, o.octree.maxAngleDeg, o.octree.outlierFraction,
      o.normalNeighbours, o.maxPageSize, int(o.compressPages), o.heightStep, o.normalTolerance, o.colourTolerance, o.pageLevel,
      int(o.storeLevels), o.gapReach);
  XXH3_64bits_update(st, opts, size_t(n));
  if (o.sparseReachAuto) {  // newer options: hashed only when given, so older packs stay current
    XXH3_64bits_update(st, " sparse-reach auto", 18);
  } else if (o.sparseReach != PackOptions{}.sparseReach) {
    const int m = std::snprintf(opts, sizeof(opts), " sparse-reach %.17g", o.sparseReach);
    XXH3_64bits_update(st, opts, size_t(m));
  }
  for (const Eigen::Vector3d& t : input.towardScanner()) XXH3_64bits_update(st, t.data(), 3 * sizeof(double));
  std::vector<char> buf(1 << 20);
  for (const InputFile& f : input.files()) {
    BufferedReader in;
    Status s = in.open(f.path, 1 << 12);
    if (!s) {
      XXH3_freeState(st);
      return s;
    }
    const uint64_t size = in.fileSize();
    XXH3_64bits_update(st, &size, sizeof(size));
    for (int a = 0; a < 9; ++a) XXH3_64bits_update(st, &f.rotation(a), sizeof(double));
    XXH3_64bits_update(st, f.translation.data(), 3 * sizeof(double));
    if (!f.hasFaces) continue;  // points: hashed as they are read for their bounds (computeBounds)
    // Faces are not streamed by the bounds pass: a mesh file is hashed whole (meshes are small
    // beside point clouds).
    std::FILE* fp = std::fopen(f.path.c_str(), "rb");
    if (!fp) {
      XXH3_freeState(st);
      return Status::badInput(f.path + ": cannot open");
    }
    size_t got;
    while ((got = std::fread(buf.data(), 1, buf.size(), fp)) > 0) XXH3_64bits_update(st, buf.data(), got);
    std::fclose(fp);
  }
  const uint64_t h = XXH3_64bits_digest(st);
  XXH3_freeState(st);
  return h;
}

static uint64_t combineHash(uint64_t setup, uint64_t content) {
  const uint64_t both[2] = {setup, content};
  const uint64_t h = XXH3_64bits(both, sizeof both);
  return h == 0 ? 1 : h;
}

namespace {

// Rank 0 (or the lone process): the input hash, bounds, the up-to-date check, distribution.
Status rootPhases(PackJob& job, const std::string& outPath, Clock::time_point tStart) {
  PackSummary& sum = job.sum;
  auto setup = hashSetup(job.input, job.opt);
  if (!setup) return setup.status();
  sum.hashSeconds = secondsSince(tStart);
  SA_RETURN_IF_ERROR(boundsPhase(job));  // also hashes the points as they are read
  sum.inputHash = combineHash(*setup, job.bounds.contentHash);
  PackReader existing;
  if (!job.opt.force && std::filesystem::exists(outPath) && existing.open(outPath, PageLoad::kNone).isOk() &&
      existing.meta().inputHash == sum.inputHash) {
    summarizeExisting(existing, sum);
    sum.upToDate = true;
    sum.seconds[5] = secondsSince(tStart);
    return Status::ok();
  }
  sum.fromTriangles = job.triangles;
  sum.normalsEstimated = !job.fileNormals && !job.triangles;
  sum.hasColor = job.color && !job.triangles;
  return distributePhase(job, outPath);
}

template <class IO, class M>
void ioMatrix(IO& io, M& m) {
  for (Eigen::Index i = 0; i < m.size(); ++i) io.io(m.data()[i]);
}

// What rootPhases leaves for the passes that follow; the chunk files themselves are on the
// filesystem the ranks share.
template <class IO>
void rootState(IO& io, PackJob& job) {
  PackSummary& s = job.sum;
  io.io(s.pointsRead), io.io(s.pointsSkipped), io.io(s.warnings), io.io(s.inputHash), io.io(s.hashSeconds);
  io.io(s.triangles), io.io(s.surfaceSamples), io.io(s.chunks), io.io(s.chunksHeld), io.io(s.fromTriangles), io.io(s.normalsEstimated);
  io.io(s.hasColor), io.io(s.upToDate), io.io(s.seconds), io.io(s.cpuSeconds), io.io(job.color);
  BoundsInfo& b = job.bounds;
  ioMatrix(io, b.min), ioMatrix(io, b.max), ioMatrix(io, b.centroid), ioMatrix(io, b.covariance);
  io.io(b.count), io.io(b.skipped), io.io(b.colorVaries), io.io(b.contentHash);
  ioMatrix(io, job.origin), ioMatrix(io, job.sheetSide), ioMatrix(io, job.qz.cubeMin), io.io(job.qz.cubeSize);
  DistributeResult& d = job.dist;
  uint64_t n = d.chunks.size();
  io.io(n);
  d.chunks.resize(n);
  for (ChunkInfo& c : d.chunks) io.io(c.path), io.io(c.count), io.io(c.level), io.io(c.ix), io.io(c.iy), io.io(c.iz);
  io.io(d.triangles), io.io(d.surfaceSamples), io.io(d.surfaceSampleStep), io.io(d.trianglePath);
  io.io(d.vertexPos), io.io(d.vertexNormal), io.io(d.vertexCone);
}

// Cluster pack: every rank learns rank 0's outcome and, when it went on, its state.
Status shareRootPhases(PackJob& job, const Status& s) {
  SA_RETURN_IF_ERROR(Cluster::agree(s));
  if (!Cluster::distributed()) return Status::ok();
  ByteWriter w;
  if (Cluster::rank() == 0) rootState(w, job);
  Cluster::broadcast(w.bytes());
  if (Cluster::rank() != 0) {
    ByteReader r(w.bytes());
    rootState(r, job);
  }
  return Status::ok();
}

// Rank 0 creates the output's temporary; the other ranks write their tiles into it.
Status openWriter(const PackJob& job, const std::string& outPath, PackWriter& writer) {
  const std::string note = makeNote(job);
  const bool snapped = effectivePrecision(job.opt, job.triangles).normalTolerance > 0;  // reducePrecision
  writer.setCompressPages(job.opt.compressPages, job.opt.pageLevel, job.opt.storeLevels,
                          snapped ? TileForm::kPyramid : TileForm::kSmaller);
  // Compressed pages: every rank codes its tiles into a temporary of its own (joinTiles).
  const bool own = job.opt.compressPages || Cluster::rank() == 0;
  Status s = own ? writer.open(outPath, job.meta, job.records, note) : Status::ok();
  SA_RETURN_IF_ERROR(Cluster::agree(s));
  if (!Cluster::distributed() || job.opt.compressPages) return Status::ok();
  ByteWriter w;
  if (Cluster::rank() == 0) w.put(writer.tempPath());
  Cluster::broadcast(w.bytes());
  if (Cluster::rank() != 0) {
    ByteReader r(w.bytes());
    std::string temp;
    r.get(temp);
    s = writer.join(temp, job.meta, job.records, note);
  }
  return Cluster::agree(s);
}

// Rank 0: META with the timings (zero when reproducible), checksums, the rename into place.
Status writePack(PackJob& job, PackWriter& writer, const std::string& outPath, const PhaseTimer& whole) {
  PackSummary& sum = job.sum;
  const PhaseTimer write;
  if (job.progress) job.progress("write", 0, 1);
  if (!job.opt.reproducible) {
    for (int i = 0; i < 4; ++i) job.meta.seconds[i] = sum.seconds[i];
    job.meta.seconds[5] = secondsSince(whole.wall);
  }
  writer.setMeta(job.meta);
  SA_RETURN_IF_ERROR(writer.finish());
  write.stop(sum, 4);
  whole.stop(sum, 5);
  sum.cpuSeconds[5] += job.otherCpu;
  sum.scratchBytes = chunkBytesWritten() - job.scratch0 + job.otherScratch[0];
  sum.scratchRawBytes = chunkRecordBytesWritten() - job.raw0 + job.otherScratch[1];
  sum.codedScratchBytes += writer.codedBytes();
  if (job.progress) job.progress("write", 1, 1);
  auto sz = fileSize(outPath);
  sum.fileBytes = sz ? *sz : 0;
  return Status::ok();
}

}  // namespace

Status packInput(const InputSet& input, const std::string& outPath, const PackOptions& opt,
                 const ProgressFn& progress, PackSummary& sum) {
  const PhaseTimer whole;
  sum = PackSummary{};
  sum.warnings = input.warnings();
  sum.threads = static_cast<uint32_t>(Cluster::threads());
  PackJob job(input, opt, progress, sum);
  job.triangles = input.hasTriangles() && !opt.asPoints;
  job.fileNormals = input.allHaveNormals();
  job.scratch0 = chunkBytesWritten();
  job.raw0 = chunkRecordBytesWritten();
  SA_RETURN_IF_ERROR(shareRootPhases(job, Cluster::rank() == 0 ? rootPhases(job, outPath, whole.wall) : Status::ok()));
  if (sum.upToDate) return Status::ok();
  SA_RETURN_IF_ERROR(cellsPhase(job));
  upPhase(job);
  const PhaseTimer heightmaps;
  if (job.triangles) SA_RETURN_IF_ERROR(assignPhase(job));
  layoutPhase(job);
  job.meta = makeMeta(job);
  PackWriter writer;
  SA_RETURN_IF_ERROR(openWriter(job, outPath, writer));
  const Status tiles = tilesPhase(job, writer);
  heightmaps.stop(sum, 3);  // layout included
  SA_RETURN_IF_ERROR(joinTiles(job, writer, tiles));
  return Cluster::agree(Cluster::rank() == 0 ? writePack(job, writer, outPath, whole) : Status::ok());
}

}  // namespace sa
