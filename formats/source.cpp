#include "formats/source.h"

#include <algorithm>
#include <filesystem>

#include "common/fileio.h"
#include "formats/conf.h"
#include "formats/draco.h"
#include "formats/isolate.h"
#include "formats/pcd.h"
#include "formats/las.h"
#include "formats/mesh_openmesh.h"
#include "formats/text.h"
#include "formats/ply.h"

namespace sa {
namespace {

Status addPly(const std::string& path, std::vector<InputFile>& out, std::vector<std::string>& warnings) {
  Result<PlyHeader> h = readPlyHeader(path);
  if (!h) return h.status();
  InputFile f;
  f.path = path;
  f.points = h->vertexCount;
  f.hasNormals = h->hasNormals;
  f.hasColors = h->hasColors;
  f.hasFaces = h->hasFaces;
  f.hasIntensity = h->hasIntensity;
  f.hasConfidence = h->hasConfidence;
  f.hasClassification = h->hasClassification;
  f.detail = h->format == PlyFormat::kAscii ? "ascii" : h->format == PlyFormat::kBinaryLittle ? "binary_little_endian" : "binary_big_endian";
  for (auto& w : h->warnings) warnings.push_back(w);
  out.push_back(f);
  return Status::ok();
}

Status addLas(const std::string& path, std::vector<InputFile>& out, bool& terrainLike) {
  Result<LasHeader> h = readLasHeader(path);
  if (!h) return h.status();
  const double dz = h->max[2] - h->min[2];
  const double dxy = std::max(h->max[0] - h->min[0], h->max[1] - h->min[1]);
  terrainLike = dxy > 0 && dz < 0.2 * dxy;
  InputFile f;
  f.path = path;
  f.format = InputFormat::kLas;
  f.points = h->pointCount;
  f.hasColors = h->hasColor;
  f.hasIntensity = true;
  f.hasClassification = true;
  f.detail = "LAS " + std::to_string(h->versionMajor) + "." + std::to_string(h->versionMinor) + ", point format " +
             std::to_string(h->pointFormat) + (h->hasColor ? (h->color8bit ? ", 8-bit colour in 16-bit fields" : ", 16-bit colour") : "");
  if (h->colorConstant)
    f.detail += ", RGB fields all " + std::to_string(h->constantColor[0]) + "," + std::to_string(h->constantColor[1]) + "," +
                std::to_string(h->constantColor[2]) + " (no colour)";
  f.up = Eigen::Vector3d::UnitZ();  // georeferenced: z up
  f.upIsConvention = true;
  out.push_back(f);
  return Status::ok();
}

// Stanford's scans carry three "bye" header lines each: one warning line per kind of skipped
// header line (with a count and the first place), not one per line of every file.
std::vector<std::string> summarizeWarnings(const std::vector<std::string>& in) {
  const std::string marker = ": skipped unknown header line ";
  struct Group { std::string first; size_t lines = 0; std::vector<std::string> files; };
  std::vector<std::pair<std::string, Group>> groups;
  std::vector<std::string> out;
  for (const std::string& w : in) {
    const size_t at = w.find(marker);
    if (at == std::string::npos) {
      out.push_back(w);
      continue;
    }
    const std::string text = w.substr(at + marker.size());
    const std::string file = w.substr(0, w.rfind(':', at - 1));
    auto g = std::find_if(groups.begin(), groups.end(), [&](const auto& e) { return e.first == text; });
    if (g == groups.end()) {
      groups.push_back({text, Group{w.substr(0, at), 0, {}}});
      g = groups.end() - 1;
    }
    ++g->second.lines;
    if (std::find(g->second.files.begin(), g->second.files.end(), file) == g->second.files.end()) g->second.files.push_back(file);
  }
  for (const auto& [text, g] : groups) {
    if (g.lines == 1) {
      out.push_back(g.first + marker + text);
      continue;
    }
    out.push_back("skipped " + std::to_string(g.lines) + " unknown header lines " + text + " in " +
                  std::to_string(g.files.size()) + " file(s), first at " + g.first + " (Stanford's scans have them)");
  }
  return out;
}

// Adapts one file's batches: alignment transform, scan index, attribute harmonisation.
class FileAdapter : public BatchSink {
 public:
  FileAdapter(BatchSink& next, const InputFile& f, bool keepNormals, bool wantColors, bool keepI, bool keepC,
              bool keepK, uint64_t base)
      : next_(next), f_(f), keepNormals_(keepNormals), wantColors_(wantColors), keepI_(keepI), keepC_(keepC),
        keepK_(keepK), base_(base) {}
  Status onPoints(const PointBatch& in) override {
    const bool drop = (!keepI_ && in.hasIntensity()) || (!keepC_ && in.hasConfidence()) ||
                      (!keepK_ && in.hasClassification());
    const bool touch = f_.transformed || (!keepNormals_ && in.hasNormals()) || drop ||
                       (wantColors_ && !in.hasColors()) || f_.scanIndex >= 0 || base_ != 0;
    if (!touch) return next_.onPoints(in);
    out_ = in;
    out_.firstIndex = in.firstIndex + base_;
    const size_t n = in.size();
    if (f_.transformed) {
      for (size_t i = 0; i < n; ++i) {
        Eigen::Vector3d p = f_.rotation * Eigen::Vector3d(in.x[i], in.y[i], in.z[i]) + f_.translation;
        out_.x[i] = p.x(); out_.y[i] = p.y(); out_.z[i] = p.z();
        if (keepNormals_ && in.hasNormals()) {
          Eigen::Vector3d nn = f_.rotation * Eigen::Vector3d(in.nx[i], in.ny[i], in.nz[i]);
          out_.nx[i] = float(nn.x()); out_.ny[i] = float(nn.y()); out_.nz[i] = float(nn.z());
        }
      }
    }
    if (!keepNormals_) { out_.nx.clear(); out_.ny.clear(); out_.nz.clear(); }
    if (!keepI_) out_.intensity.clear();
    if (!keepC_) out_.confidence.clear();
    if (!keepK_) out_.classification.clear();
    if (wantColors_ && !in.hasColors()) { out_.r.assign(n, 255); out_.g.assign(n, 255); out_.b.assign(n, 255); }
    if (f_.scanIndex >= 0) out_.scan.assign(n, static_cast<uint16_t>(f_.scanIndex));
    return next_.onPoints(out_);
  }
  Status onTriangles(const uint32_t* idx, size_t n) override { return next_.onTriangles(idx, n); }

 private:
  BatchSink& next_;
  const InputFile& f_;
  bool keepNormals_, wantColors_, keepI_, keepC_, keepK_;
  uint64_t base_;
  PointBatch out_;
};

}  // namespace

namespace {

// What every reader's header or count tells of a file.
InputFile fileOf(const std::string& path, InputFormat format, uint64_t points, bool normals, bool colors, bool intensity) {
  InputFile f;
  f.path = path;
  f.format = format;
  f.points = points;
  f.hasNormals = normals;
  f.hasColors = colors;
  f.hasIntensity = intensity;
  return f;
}

// OpenMesh parses the whole file even to count: record what it delivers and replay that.
Result<InputFile> meshFile(const std::string& path, const std::string& ext) {
  auto rec = std::make_shared<StreamRecording>(kDefaultBatchPoints);
  SA_RETURN_IF_ERROR(readMesh(path, kDefaultBatchPoints, true, *rec));
  rec->finish();
  InputFile f = fileOf(path, InputFormat::kMesh, rec->points(), rec->anyNormals(), rec->anyColors(), false);
  f.hasFaces = rec->triangles() > 0;
  f.recording = std::move(rec);
  f.up = ext == ".stl" ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitY();  // STL comes from CAD: z up
  return f;
}

Result<InputFile> pcdFile(const std::string& path) {
  auto h = readPcdHeader(path);
  if (!h) return h.status();
  InputFile f = fileOf(path, InputFormat::kPcd, h->points, h->hasNormals, h->hasColors, h->hasIntensity);
  const char* enc[] = {"ascii", "binary", "binary_compressed"};
  f.detail = std::string(enc[int(h->encoding)]) +
             (h->organized() ? ", organized " + std::to_string(h->width) + "x" + std::to_string(h->height) : ", unorganized");
  if (h->organized()) {
    // An organized cloud is a camera's image: y points down the image.
    f.up = -Eigen::Vector3d::UnitY();
    f.upIsConvention = f.upFromCamera = true;
  }
  return f;
}

// libdraco decodes the whole file even to count: record what it delivers and replay that.
Result<InputFile> dracoFile(const std::string& path) {
  auto rec = std::make_shared<StreamRecording>(kDefaultBatchPoints);
  DracoInfo info;
  SA_RETURN_IF_ERROR(readDraco(path, kDefaultBatchPoints, true, *rec, &info));
  rec->finish();
  InputFile f = fileOf(path, InputFormat::kDraco, info.points, info.hasNormals, info.hasColors, info.hasIntensity);
  f.hasFaces = info.triangles > 0;
  f.hasConfidence = info.hasConfidence;
  f.hasClassification = info.hasClassification;
  f.detail = info.triangles ? "mesh, " + std::to_string(info.triangles) + " triangles" : "point cloud";
  if (info.shifted) f.detail += ", positions relative to a recorded origin";
  f.recording = std::move(rec);
  f.up = Eigen::Vector3d::UnitY();
  return f;
}

Result<InputFile> textFile(const std::string& path, const std::string& textColumns) {
  auto layout = readTextLayout(path, textColumns);
  if (!layout) return layout.status();
  InputFile f = fileOf(path, InputFormat::kText, layout->dataLines, layout->hasNormals, layout->hasColors, layout->hasIntensity);
  f.hasConfidence = layout->hasConfidence;
  f.hasClassification = layout->hasClassification;
  f.columns = textColumns;
  f.up = Eigen::Vector3d::UnitY();
  return f;
}

}  // namespace

// A Stanford scan set: one PLY range grid per scan, each with its pose and scanner direction.
Status InputSet::addConf(const std::string& path) {
  auto scans = readConf(path);
  if (!scans) return scans.status();
  for (const auto& s : *scans) {
    SA_RETURN_IF_ERROR(addPly(s.path, files_, warnings_));
    InputFile& f = files_.back();
    f.transformed = true;
    f.rotation = s.rotation;
    f.translation = s.translation;
    f.scanIndex = static_cast<int>(towardScanner_.size());
    f.hasFaces = false;  // range grids are not triangles
    f.up = Eigen::Vector3d::UnitY();  // Stanford's scans are y-up
    f.upIsConvention = true;
    towardScanner_.push_back(s.towardScanner);
  }
  return Status::ok();
}

Status InputSet::addLasFile(const std::string& path) {
  bool terrainLike = false;
  SA_RETURN_IF_ERROR(addLas(path, files_, terrainLike));
  // LAS is georeferenced with z up. Airborne data (flat and wide: height range under a fifth of
  // the horizontal extent) is seen from above: estimated normals face +z. Terrestrial scans
  // keep the default (away from the centroid).
  if (terrainLike) {
    files_.back().scanIndex = static_cast<int>(towardScanner_.size());
    towardScanner_.push_back(Eigen::Vector3d::UnitZ());
  }
  return Status::ok();
}

Status InputSet::add(const std::string& path, const std::string& textColumns) {
  const std::string ext = lowerExtension(path);
  if (ext == ".conf") return addConf(path);
  if (ext == ".ply") {
    SA_RETURN_IF_ERROR(addPly(path, files_, warnings_));
    files_.back().up = Eigen::Vector3d::UnitY();
    return Status::ok();
  }
  if (ext == ".las" || ext == ".laz") return addLasFile(path);
  Result<InputFile> f = Status::badInput(path + ": unsupported input format '" + ext +
                                         "' (supported: .ply, .conf scan sets, .pcd, .drc, .las, .obj/.off/.stl, .xyz/.pts/.csv/.txt)");
  if (ext == ".obj" || ext == ".off" || ext == ".stl") f = meshFile(path, ext);
  else if (ext == ".pcd") f = pcdFile(path);
  else if (ext == ".drc") f = dracoFile(path);
  else if (ext == ".xyz" || ext == ".pts" || ext == ".csv" || ext == ".txt") f = textFile(path, textColumns);
  if (!f) return f.status();
  files_.push_back(std::move(*f));
  return Status::ok();
}

Result<InputSet> InputSet::open(const std::vector<std::string>& paths, const std::string& textColumns) {
  InputSet set;
  if (paths.empty()) return Status::badInput("no input files given");
  for (const auto& path : paths) {
    std::error_code ec;
    const auto abs = std::filesystem::absolute(path, ec);
    set.sourcePaths_.push_back(ec ? path : abs.lexically_normal().string());
    SA_RETURN_IF_ERROR(set.add(path, textColumns));
  }
  if (set.files_.size() > 1) {
    for (auto& f : set.files_) {
      if (f.hasFaces) {
        set.warnings_.push_back(f.path + ": faces ignored (several inputs are packed as points)");
        f.hasFaces = false;
      }
    }
  }
  if (set.pointCount() == 0) return Status::badInput(paths[0] + ": the input holds no points");
  set.warnings_ = summarizeWarnings(set.warnings_);
  return set;
}

uint64_t InputSet::pointCount() const {
  uint64_t n = 0;
  for (const auto& f : files_) n += f.points;
  return n;
}

std::pair<std::string, uint64_t> InputSet::locate(uint64_t i) const {
  for (const auto& f : files_) {
    if (i < f.points) return {f.path, i};
    i -= f.points;
  }
  return {files_.empty() ? std::string() : files_.back().path, i};
}

bool InputSet::allHaveNormals() const {
  return std::all_of(files_.begin(), files_.end(), [](const InputFile& f) { return f.hasNormals; });
}

bool InputSet::allHaveIntensity() const {
  return std::all_of(files_.begin(), files_.end(), [](const InputFile& f) { return f.hasIntensity; });
}

bool InputSet::allHaveConfidence() const {
  return std::all_of(files_.begin(), files_.end(), [](const InputFile& f) { return f.hasConfidence; });
}

bool InputSet::allHaveClassification() const {
  return std::all_of(files_.begin(), files_.end(), [](const InputFile& f) { return f.hasClassification; });
}

const char* formatName(InputFormat f) {
  switch (f) {
    case InputFormat::kPly: return "PLY";
    case InputFormat::kLas: return "LAS";
    case InputFormat::kText: return "text";
    case InputFormat::kMesh: return "OBJ/OFF/STL";
    case InputFormat::kPcd: return "PCD";
    case InputFormat::kDraco: return "Draco";
  }
  return "?";
}

bool InputSet::anyHasColors() const {
  return std::any_of(files_.begin(), files_.end(), [](const InputFile& f) { return f.hasColors; });
}

Status InputSet::stream(BatchSink& sink, bool readTriangles, size_t batchPoints) const {
  const bool keepNormals = allHaveNormals();
  const bool wantColors = anyHasColors();
  uint64_t base = 0;
  for (const auto& f : files_) {
    FileAdapter adapter(sink, f, keepNormals, wantColors, allHaveIntensity(), allHaveConfidence(),
                        allHaveClassification(), base);
    if (f.recording && f.recording->replayable(batchPoints)) {
      SA_RETURN_IF_ERROR(f.recording->replay(adapter, readTriangles && hasTriangles()));
    } else if (f.format == InputFormat::kLas) {
      SA_RETURN_IF_ERROR(readLas(f.path, batchPoints, adapter));
    } else if (f.format == InputFormat::kPcd) {
      SA_RETURN_IF_ERROR(readPcd(f.path, batchPoints, adapter));
    } else if (f.format == InputFormat::kDraco) {
      SA_RETURN_IF_ERROR(readDraco(f.path, batchPoints, readTriangles && hasTriangles(), adapter));
    } else if (f.format == InputFormat::kMesh) {
      SA_RETURN_IF_ERROR(readMesh(f.path, batchPoints, readTriangles && hasTriangles(), adapter));
    } else if (f.format == InputFormat::kText) {
      auto layout = readTextLayout(f.path, f.columns);
      if (!layout) return layout.status();
      SA_RETURN_IF_ERROR(readText(f.path, *layout, batchPoints, adapter));
    } else {
      PlyReadOptions opt;
      opt.batchPoints = batchPoints;
      opt.readFaces = readTriangles && hasTriangles();
      SA_RETURN_IF_ERROR(readPly(f.path, opt, adapter));
    }
    base += f.points;
  }
  return Status::ok();
}

}  // namespace sa
