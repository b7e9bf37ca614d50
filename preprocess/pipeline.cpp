#include "preprocess/pipeline.h"

#include <xxhash.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <unordered_map>

#include "atlas/pack_file.h"
#include "atlas/packing.h"
#include "common/fileio.h"
#include "preprocess/normals.h"
#include "preprocess/pullpush.h"

namespace sa {
namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

struct WorkCell {
  CellRecord rec{};
  uint32_t chunk = 0, first = 0, count = 0;
  double ext[6] = {0, 0, 0, 0, 0, 0};  // raw point extents in the frame: uMin uMax vMin vMax wMin wMax
};

void decodePositions(const std::vector<ChunkPoint>& pts, const Quantizer& qz, std::vector<double>& pos) {
  pos.resize(pts.size() * 3);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pts.size(), 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i)
      for (int a = 0; a < 3; ++a) pos[3 * i + a] = qz.decode(pts[i].q[a], a);
  });
}

Eigen::Vector3d vec(const double* d) { return Eigen::Vector3d(d[0], d[1], d[2]); }

// Fills the summary from an existing pack (the up-to-date case).
void summarizeExisting(const PackReader& r, PackSummary& sum) {
  const PackMeta& m = r.meta();
  sum.pointsRead = m.sourcePoints;
  sum.pointsSkipped = m.skippedPoints;
  sum.triangles = m.sourceTriangles;
  sum.cells = m.cellCount;
  sum.pages = m.pageCount;
  sum.pageSize = m.pageSize;
  sum.chunks = m.chunkCount;
  sum.texels = m.texelsUsed;
  sum.spacing = m.sampleSpacing;
  sum.texelSize = m.texelSize;
  sum.fileBytes = r.fileBytes();
  sum.hasColor = r.hasColor();
  sum.fromTriangles = (m.flags & kPackFromTriangles) != 0;
  sum.normalsEstimated = (m.flags & kPackNormalsEstimated) != 0;
  for (const CellRecord& c : r.cells()) {
    if (c.level >= sum.cellsPerLevel.size()) sum.cellsPerLevel.resize(c.level + 1, 0);
    ++sum.cellsPerLevel[c.level];
    sum.forcedCells += (c.flags & kCellForced) != 0;
    sum.degenerateCells += (c.flags & kCellDegenerate) != 0;
  }
}

}  // namespace

Result<uint64_t> hashInput(const InputSet& input, const PackOptions& o) {
  XXH3_state_t* st = XXH3_createState();
  XXH3_64bits_reset(st);
  char opts[512];
  // kPipelineRevision changes whenever packing changes what it writes for the same input, so
  // packs made by an older build are not mistaken for up to date.
  constexpr int kPipelineRevision = 2;
  const int n = std::snprintf(opts, sizeof(opts), "r%d f%u %llu %llu %.17g %.17g %.17g %d %d %.17g %u %.17g %d %u",
                              kPipelineRevision, kPackVersion, (unsigned long long)o.memBudget, (unsigned long long)o.texelBudget, o.texelSize,
                              o.texelPerSpacing, o.coverageRadius, int(o.asPoints), o.octree.maxDepth,
                              o.octree.maxAngleDeg, o.octree.minSplitPoints, o.octree.outlierFraction,
                              o.normalNeighbours, o.maxPageSize);
  XXH3_64bits_update(st, opts, size_t(n));
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
  return h == 0 ? 1 : h;
}

Status packInput(const InputSet& input, const std::string& outPath, const PackOptions& opt,
                 const ProgressFn& progress, PackSummary& sum) {
  const auto tStart = Clock::now();
  sum = PackSummary{};
  sum.warnings = input.warnings();
  {
    auto h = hashInput(input, opt);
    if (!h) return h.status();
    sum.inputHash = *h;
    sum.hashSeconds = secondsSince(tStart);
    PackReader existing;
    if (!opt.force && std::filesystem::exists(outPath) && existing.open(outPath).isOk() &&
        existing.meta().inputHash == sum.inputHash) {
      summarizeExisting(existing, sum);
      sum.upToDate = true;
      sum.seconds[5] = secondsSince(tStart);
      return Status::ok();
    }
  }
  const bool triangles = input.hasTriangles() && !opt.asPoints;
  const bool fileNormals = input.allHaveNormals();
  const bool color = input.anyHasColors();
  sum.fromTriangles = triangles;
  sum.hasColor = color;
  sum.normalsEstimated = !fileNormals && !triangles;

  // ---- pass 1: bounds ----
  auto t0 = Clock::now();
  BoundsInfo bounds;
  SA_RETURN_IF_ERROR(computeBounds(input, bounds, progress, opt.strict));
  sum.pointsRead = bounds.count;
  sum.pointsSkipped = bounds.skipped;
  sum.seconds[0] = secondsSince(t0);
  const Eigen::Vector3d origin = (bounds.min + bounds.max) / 2;
  const Eigen::Vector3d ext = bounds.max - bounds.min;
  Quantizer qz;
  qz.cubeSize = std::max(ext.maxCoeff() * 1.0001, std::max(1e-12, 1e-12 * origin.cwiseAbs().maxCoeff()));
  qz.cubeMin = Eigen::Vector3d::Constant(-qz.cubeSize / 2);

  // ---- pass 2: distribute into chunks ----
  t0 = Clock::now();
  // Leftovers of a killed pack (chunk directories, a partial output) are removed, not reused.
  const std::string scratchParent = opt.scratchParent.empty() ? directoryOf(outPath) : opt.scratchParent;
  removeStaleTemporaries(scratchParent, ".scanatlas-chunks-");
  removeStaleTemporaries(directoryOf(outPath), std::filesystem::path(outPath).filename().string() + ".tmp-");
  ScratchDir scratch;
  SA_RETURN_IF_ERROR(scratch.create(scratchParent, ".scanatlas-chunks-"));
  DistributeOptions dopt;
  dopt.maxPointsPerChunk = std::max<uint64_t>(1024, opt.memBudget / kBytesPerPointInFlight);
  dopt.scratchDir = scratch.path();
  dopt.origin = origin;
  dopt.keepTriangles = triangles;
  DistributeResult dist;
  SA_RETURN_IF_ERROR(distributePoints(input, qz, dopt, dist, progress));
  sum.triangles = dist.triangles;
  sum.chunks = static_cast<uint32_t>(dist.chunks.size());
  sum.seconds[1] = secondsSince(t0);
  if (triangles && dist.triangles == 0) {
    return Status::badInput(input.files()[0].path + ": face element holds no triangles; use --as-points");
  }

  // ---- pass A: normals + octree per chunk ----
  t0 = Clock::now();
  std::vector<WorkCell> cells;
  std::vector<uint32_t> vertexCell;
  if (triangles) vertexCell.assign(dist.vertexPos.size() / 3, UINT32_MAX);
  double spacingSum = 0;
  uint64_t spacingWeight = 0;
  uint64_t processed = 0;
  const uint64_t total = bounds.count;
  std::vector<ChunkPoint> pts;
  std::vector<double> pos;
  std::vector<float> nrm;
  NormalOrientation orient;
  orient.towardScanner = input.towardScanner();
  orient.center = bounds.centroid - origin;
  for (uint32_t ci = 0; ci < dist.chunks.size(); ++ci) {
    const ChunkInfo& ch = dist.chunks[ci];
    SA_RETURN_IF_ERROR(loadChunk(ch, pts));
    decodePositions(pts, qz, pos);
    const size_t n = pts.size();
    nrm.assign(3 * n, 0.f);
    if (fileNormals) {
      for (size_t i = 0; i < n; ++i) std::copy(pts[i].n, pts[i].n + 3, &nrm[3 * i]);
    } else if (triangles) {
      for (size_t i = 0; i < n; ++i) {
        const size_t v = pts[i].vid;
        if (3 * v + 2 < dist.vertexNormal.size()) {
          Eigen::Vector3f nn(&dist.vertexNormal[3 * v]);
          if (nn.norm() > 0) nn.normalize();
          std::copy(nn.data(), nn.data() + 3, &nrm[3 * i]);
        }
      }
    } else {
      orient.scan = &pts[0].scan;
      orient.scanStride = sizeof(ChunkPoint);
      estimateNormals(pos.data(), n, opt.normalNeighbours, orient, nrm.data());
    }
    const double sp = estimateSpacing(pos.data(), n);
    if (sp > 0) {
      spacingSum += sp * double(n);
      spacingWeight += n;
    }
    std::vector<uint32_t> idx(n);
    for (uint32_t i = 0; i < n; ++i) idx[i] = i;
    Eigen::Vector3d cmin;
    double csize;
    nodeCube(qz, ch.level, ch.ix, ch.iy, ch.iz, cmin, csize);
    std::vector<OctreeCell> oc;
    OctreeParams op = opt.octree;
    op.maxDepth = std::max(op.maxDepth, ch.level);
    buildOctree(pos.data(), nrm.data(), idx, cmin, csize, ch.level, op, oc);
    // Rewrite the chunk in cell order with its normals, for pass B.
    std::vector<ChunkPoint> sorted(n);
    for (size_t i = 0; i < n; ++i) {
      sorted[i] = pts[idx[i]];
      std::copy(&nrm[3 * size_t(idx[i])], &nrm[3 * size_t(idx[i])] + 3, sorted[i].n);
    }
    SA_RETURN_IF_ERROR(saveChunk(ch.path, sorted));
    for (const OctreeCell& c : oc) {
      WorkCell wc;
      wc.chunk = ci;
      wc.first = c.first;
      wc.count = c.count;
      const PlaneFit& f = c.fit;
      for (int a = 0; a < 3; ++a) {
        wc.rec.origin[a] = f.centroid[a];
        wc.rec.u[a] = f.u[a];
        wc.rec.v[a] = f.v[a];
        wc.rec.w[a] = f.w[a];
      }
      wc.rec.level = static_cast<uint8_t>(std::min(c.level, 255));
      wc.rec.flags = (c.forced ? kCellForced : 0) | (f.degenerate ? kCellDegenerate : 0);
      wc.rec.pointCount = c.count;
      double e[6] = {1e300, -1e300, 1e300, -1e300, 1e300, -1e300};
      for (uint32_t k = c.first; k < c.first + c.count; ++k) {
        const Eigen::Vector3d d = vec(&pos[3 * size_t(idx[k])]) - f.centroid;
        const double uvw[3] = {d.dot(f.u), d.dot(f.v), d.dot(f.w)};
        for (int a = 0; a < 3; ++a) {
          e[2 * a] = std::min(e[2 * a], uvw[a]);
          e[2 * a + 1] = std::max(e[2 * a + 1], uvw[a]);
        }
        if (triangles) vertexCell[sorted[k].vid] = static_cast<uint32_t>(cells.size());
      }
      std::copy(e, e + 6, wc.ext);
      cells.push_back(wc);
    }
    processed += n;
    if (progress) progress("octree", processed, total);
  }
  pts.clear(); pts.shrink_to_fit();
  sum.seconds[2] = secondsSince(t0);
  if (cells.empty()) return Status::badInput(input.files()[0].path + ": no cells produced");
  if (cells.size() > 16u << 20) return Status::badInput("more than 16 Mi cells; lower --max-depth");

  // ---- texel size, tiles, atlas layout ----
  t0 = Clock::now();
  sum.spacing = spacingWeight ? spacingSum / double(spacingWeight) : qz.cubeSize * 1e-3;
  if (!(sum.spacing > 0)) sum.spacing = qz.cubeSize * 1e-3;
  const double cover = opt.coverageRadius * sum.spacing;
  // Triangles need no coverage radius (their own extent is the coverage), but a texel of
  // padding keeps neighbouring cells' edges from leaving cracks.
  double t = opt.texelSize > 0 ? opt.texelSize : sum.spacing * opt.texelPerSpacing;
  const double padUV = triangles ? 0.0 : cover;
  double area = 0;
  for (const WorkCell& c : cells)
    area += (c.ext[1] - c.ext[0] + 2 * padUV + t) * (c.ext[3] - c.ext[2] + 2 * padUV + t);
  if (opt.texelSize <= 0) t = std::max(t, std::sqrt(area / double(opt.texelBudget)));
  const uint32_t maxTile = opt.maxPageSize - 2;
  // Triangles that touch a cell reach up to an edge length past its vertices: pad the tile
  // by that much (about 1.5 sample spacings) so neighbouring cells' coverage overlaps.
  double triPad = std::max(t, 1.5 * sum.spacing);
  std::vector<TileSize> sizes(cells.size());
  for (int iter = 0; iter < 40; ++iter) {
    uint64_t texels = 0;
    for (size_t i = 0; i < cells.size(); ++i) {
      const WorkCell& c = cells[i];
      const double pad = triangles ? triPad : padUV;
      const double eu = c.ext[1] - c.ext[0] + 2 * pad, ev = c.ext[3] - c.ext[2] + 2 * pad;
      sizes[i].w = static_cast<uint32_t>(std::clamp(std::ceil(eu / t), 1.0, double(maxTile)));
      sizes[i].h = static_cast<uint32_t>(std::clamp(std::ceil(ev / t), 1.0, double(maxTile)));
      texels += uint64_t(sizes[i].w) * sizes[i].h;
    }
    sum.texels = texels;
    if (texels <= opt.texelBudget || opt.texelSize > 0) break;
    t *= std::sqrt(double(texels) / double(opt.texelBudget)) * 1.01;
    triPad = std::max(t, 1.5 * sum.spacing);
  }
  sum.texelSize = t;
  uint64_t withGutters = 0;
  uint32_t largest = 1;
  for (const TileSize& s : sizes) {
    withGutters += uint64_t(s.w + 2) * (s.h + 2);
    largest = std::max({largest, s.w, s.h});
  }
  const uint32_t pageSize = choosePageSize(withGutters, largest, opt.maxPageSize);
  PackingResult layout = packTiles(sizes, pageSize);
  std::vector<CellRecord> records(cells.size());
  for (size_t i = 0; i < cells.size(); ++i) {
    WorkCell& c = cells[i];
    CellRecord& r = c.rec;
    const double pad = triangles ? triPad : padUV;
    const double eu = c.ext[1] - c.ext[0] + 2 * pad, ev = c.ext[3] - c.ext[2] + 2 * pad;
    // The tile spans the box exactly: widen the box to whole texels, centred on the points.
    const double su = std::max(sizes[i].w * t, eu), sv = std::max(sizes[i].h * t, ev);
    const double cu = (c.ext[0] + c.ext[1]) / 2, cv = (c.ext[2] + c.ext[3]) / 2;
    const double wpad = std::max(0.5 * t, 1e-9 * qz.cubeSize);
    r.box[0] = cu - su / 2; r.box[1] = cu + su / 2;
    r.box[2] = cv - sv / 2; r.box[3] = cv + sv / 2;
    r.box[4] = c.ext[4] - wpad; r.box[5] = c.ext[5] + wpad;
    r.page = layout.placements[i].page;
    r.tileX = layout.placements[i].x;
    r.tileY = layout.placements[i].y;
    r.tileW = static_cast<uint16_t>(sizes[i].w);
    r.tileH = static_cast<uint16_t>(sizes[i].h);
    records[i] = r;
    if (r.level >= sum.cellsPerLevel.size()) sum.cellsPerLevel.resize(r.level + 1, 0);
    ++sum.cellsPerLevel[r.level];
    if (r.flags & kCellForced) ++sum.forcedCells;
    if (r.flags & kCellDegenerate) ++sum.degenerateCells;
  }
  sum.cells = static_cast<uint32_t>(cells.size());
  sum.pages = layout.pageCount;
  sum.pageSize = pageSize;

  PackMeta meta{};
  for (int a = 0; a < 3; ++a) {
    meta.origin[a] = origin[a];
    meta.boundsMin[a] = bounds.min[a] - origin[a];
    meta.boundsMax[a] = bounds.max[a] - origin[a];
  }
  meta.texelSize = t;
  meta.sampleSpacing = sum.spacing;
  meta.sourcePoints = bounds.count;
  meta.skippedPoints = bounds.skipped;
  meta.sourceTriangles = dist.triangles;
  meta.pageSize = pageSize;
  meta.pageCount = layout.pageCount;
  meta.flags = (color && !triangles ? uint32_t(kPackHasColor) : 0u) | (triangles ? uint32_t(kPackFromTriangles) : 0u) |
               (sum.normalsEstimated ? uint32_t(kPackNormalsEstimated) : 0u);
  meta.maxDepth = static_cast<uint32_t>(opt.octree.maxDepth);
  meta.chunkCount = sum.chunks;
  meta.texelsUsed = sum.texels;
  meta.inputHash = sum.inputHash;
  // NOTE (FORMAT.md): one "source: <path>" line per input, then the command line.
  std::string note;
  for (const auto& f : input.sourcePaths()) note += "source: " + f + "\n";
  for (const auto& f : input.files())
    if (!f.columns.empty()) {
      note += "columns: " + f.columns + "\n";
      break;
    }
  note += "command: " + opt.commandLine + "\n";
  PackWriter writer;
  SA_RETURN_IF_ERROR(writer.open(outPath, meta, records, note));
  const bool writeColor = (meta.flags & kPackHasColor) != 0;

  // ---- pass B: height maps per chunk ----
  std::vector<std::vector<uint32_t>> chunkCells(dist.chunks.size());
  for (uint32_t i = 0; i < cells.size(); ++i) chunkCells[cells[i].chunk].push_back(i);
  processed = 0;
  for (uint32_t ci = 0; ci < dist.chunks.size(); ++ci) {
    SA_RETURN_IF_ERROR(loadChunk(dist.chunks[ci], pts));
    decodePositions(pts, qz, pos);
    // Triangle path: the triangles touching each cell of this chunk.
    std::unordered_map<uint32_t, std::vector<uint32_t>> cellTris;
    if (triangles) {
      std::FILE* f = std::fopen(dist.trianglePath.c_str(), "rb");
      if (!f) return Status::internal(dist.trianglePath + ": cannot reopen");
      std::vector<uint32_t> buf(3 * 65536);
      size_t got;
      uint64_t triIndex = 0;
      while ((got = std::fread(buf.data(), 12, buf.size() / 3, f)) > 0) {
        for (size_t k = 0; k < got; ++k, ++triIndex) {
          uint32_t cs[3];
          for (int j = 0; j < 3; ++j) {
            const uint32_t v = buf[3 * k + j];
            cs[j] = v < vertexCell.size() ? vertexCell[v] : UINT32_MAX;
          }
          for (int j = 0; j < 3; ++j) {
            if (cs[j] == UINT32_MAX || cells[cs[j]].chunk != ci) continue;
            if ((j > 0 && cs[j] == cs[0]) || (j > 1 && cs[j] == cs[1])) continue;
            auto& list = cellTris[cs[j]];
            list.push_back(buf[3 * k]);
            list.push_back(buf[3 * k + 1]);
            list.push_back(buf[3 * k + 2]);
          }
        }
      }
      std::fclose(f);
    }
    const auto& mine = chunkCells[ci];
    Status failed;
    std::mutex failMu;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, mine.size(), 1), [&](const tbb::blocked_range<size_t>& rr) {
      std::vector<double> u, v, w, tri;
      std::vector<uint8_t> rgb;
      TileOutput tile;
      for (size_t m = rr.begin(); m < rr.end(); ++m) {
        const uint32_t id = mine[m];
        const WorkCell& c = cells[id];
        CellRecord& r = records[id];
        const Eigen::Vector3d O = vec(r.origin), U = vec(r.u), V = vec(r.v), Wn = vec(r.w);
        TileGrid g;
        g.width = r.tileW;
        g.height = r.tileH;
        g.u0 = r.box[0];
        g.v0 = r.box[2];
        g.du = (r.box[1] - r.box[0]) / r.tileW;
        g.dv = (r.box[3] - r.box[2]) / r.tileH;
        g.wMin = r.box[4];
        g.wMax = r.box[5];
        if (triangles) {
          auto it = cellTris.find(id);
          tri.clear();
          if (it != cellTris.end()) {
            for (uint32_t vi : it->second) {
              const Eigen::Vector3d d = vec(&dist.vertexPos[3 * size_t(vi)]) - O;
              tri.push_back(d.dot(U));
              tri.push_back(d.dot(V));
              tri.push_back(d.dot(Wn));
            }
          }
          // The box's height range grows to hold the whole of every triangle touching the
          // cell (within the padding), so the parts of those triangles outside the cell's
          // own vertices are not cut where the neighbouring box does not reach either.
          double wLo = r.box[4], wHi = r.box[5];
          const double reach = std::max(r.box[1] - r.box[0], r.box[3] - r.box[2]);
          for (size_t k = 2; k < tri.size(); k += 3) {
            wLo = std::min(wLo, std::max(tri[k], r.box[4] - reach));
            wHi = std::max(wHi, std::min(tri[k], r.box[5] + reach));
          }
          r.box[4] = wLo;
          r.box[5] = wHi;
          g.wMin = wLo;
          g.wMax = wHi;
          writer.setCellHeights(id, wLo, wHi);
          rasterizeTile(g, tri.data(), tri.size() / 9, 0.5 * t, tile);
        } else {
          u.resize(c.count); v.resize(c.count); w.resize(c.count);
          rgb.resize(writeColor ? 3 * size_t(c.count) : 0);
          for (uint32_t k = 0; k < c.count; ++k) {
            const size_t pi = size_t(c.first) + k;
            const Eigen::Vector3d d = vec(&pos[3 * pi]) - O;
            u[k] = d.dot(U); v[k] = d.dot(V); w[k] = d.dot(Wn);
            if (writeColor) std::copy(pts[pi].rgb, pts[pi].rgb + 3, &rgb[3 * size_t(k)]);
          }
          pullPushTile(g, u.data(), v.data(), w.data(), writeColor ? rgb.data() : nullptr, c.count, cover, tile);
        }
        Status s = writer.writeTile(id, tile.heights.data(), writeColor ? tile.rgba.data() : nullptr);
        if (!s) {
          std::lock_guard<std::mutex> lock(failMu);
          failed = s;
        }
      }
    });
    SA_RETURN_IF_ERROR(failed);
    processed += pts.size();
    if (progress) progress("heightmaps", processed, total);
  }
  sum.seconds[3] = secondsSince(t0);
  t0 = Clock::now();
  if (progress) progress("write", 0, 1);
  meta.seconds[0] = sum.seconds[0];
  meta.seconds[1] = sum.seconds[1];
  meta.seconds[2] = sum.seconds[2];
  meta.seconds[3] = sum.seconds[3];
  meta.seconds[5] = secondsSince(tStart);
  writer.setMeta(meta);
  SA_RETURN_IF_ERROR(writer.finish());
  sum.seconds[4] = secondsSince(t0);
  sum.seconds[5] = secondsSince(tStart);
  if (progress) progress("write", 1, 1);
  auto sz = fileSize(outPath);
  sum.fileBytes = sz ? *sz : 0;
  return Status::ok();
}

}  // namespace sa
