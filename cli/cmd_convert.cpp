#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>

#include "cli/args.h"
#include "cli/commands.h"
#include "cli/progress.h"
#include "common/fileio.h"
#include "formats/draco.h"
#include "formats/source.h"
#include "formats/writers.h"

namespace sa {
namespace {

const char* kHelp =
    "usage: scanatlas convert INPUT... -o OUT.{ply,drc,xyz,txt,csv} [options]\n\n"
    "Writes the points of one or more inputs (every format `pack` reads: PLY, .conf scan sets,\n"
    "PCD, Draco, LAS, OBJ/OFF/STL vertices, XYZ/PTS/CSV/TXT) to one file, aligned as `pack` aligns\n"
    "them. The output format follows the extension:\n"
    "  .ply       binary little-endian PLY, double x y z (georeferenced coordinates keep full\n"
    "             precision), float normals, uchar colours, float intensity / confidence,\n"
    "             uchar classification when the inputs have them\n"
    "  .drc       Draco point cloud (a mesh when the input is one mesh), positions quantized to --quantization bits; generic\n"
    "             attributes named intensity / confidence / classification. Georeferenced\n"
    "             positions are stored relative to an origin recorded in the file's metadata\n"
    "  .xyz .txt  text, space-separated, a header line of column names\n"
    "  .csv       text, comma-separated, a header line of column names\n"
    "Points with a NaN or infinite coordinate are left out and counted (--strict: an error).\n"
    "Attributes are written when every input has them (colours when any has them). Streamed:\n"
    "PLY and text output use memory independent of the point count; Draco encodes all points\n"
    "at once (about 60 bytes per point while encoding).\n\n"
    "options:\n"
    "  -o, --output FILE      output file (required); written to a temporary file and renamed\n"
    "  --columns SPEC         text inputs: column roles, e.g. x,y,z,nx,ny,nz,r,g,b,i,c,confidence\n"
    "  --quantization BITS    Draco position quantization, 1-30 bits, or 0 for lossless floats\n"
    "                         (default 16: 1/65536 of the largest extent)\n"
    "  --normal-bits BITS     Draco normal quantization (default 10)\n"
    "  --draco-speed N        Draco speed 0 (smallest file) to 10 (fastest) (default 5)\n"
    "  --strict               a NaN or infinite coordinate is an error\n"
    "  --json                 print a JSON summary on stdout\n"
    "  -q, --quiet            no progress or summary on stderr\n"
    "exit codes: 0 ok, 2 bad input or usage, 1 internal failure\n";

// Drops points without finite coordinates (or stops with --strict), reports progress.
class Filter : public BatchSink {
 public:
  Filter(BatchSink& next, const InputSet& in, bool strict, Progress& progress)
      : next_(next), in_(in), strict_(strict), progress_(progress) {}
  Status onPoints(const PointBatch& b) override {
    read_ += b.size();
    size_t bad = 0;
    for (size_t i = 0; i < b.size(); ++i) bad += !(std::isfinite(b.x[i]) && std::isfinite(b.y[i]) && std::isfinite(b.z[i]));
    progress_("convert", read_, in_.pointCount());
    if (bad == 0) return next_.onPoints(b);
    if (strict_) {
      for (size_t i = 0; i < b.size(); ++i)
        if (!(std::isfinite(b.x[i]) && std::isfinite(b.y[i]) && std::isfinite(b.z[i]))) {
          const auto [file, index] = in_.locate(b.firstIndex + i);
          return Status::badInput(file + ": vertex " + std::to_string(index) +
                                  " has a NaN or infinite coordinate (--strict; without it such points are skipped)");
        }
    }
    skipped_ += bad;
    keep_.clear();
    keep_.firstIndex = b.firstIndex;
    for (size_t i = 0; i < b.size(); ++i) {
      if (!(std::isfinite(b.x[i]) && std::isfinite(b.y[i]) && std::isfinite(b.z[i]))) continue;
      keep_.x.push_back(b.x[i]); keep_.y.push_back(b.y[i]); keep_.z.push_back(b.z[i]);
      if (b.hasNormals()) { keep_.nx.push_back(b.nx[i]); keep_.ny.push_back(b.ny[i]); keep_.nz.push_back(b.nz[i]); }
      if (b.hasColors()) { keep_.r.push_back(b.r[i]); keep_.g.push_back(b.g[i]); keep_.b.push_back(b.b[i]); }
      if (b.hasIntensity()) keep_.intensity.push_back(b.intensity[i]);
      if (b.hasConfidence()) keep_.confidence.push_back(b.confidence[i]);
      if (b.hasClassification()) keep_.classification.push_back(b.classification[i]);
    }
    return keep_.size() ? next_.onPoints(keep_) : Status::ok();
  }
  // Triangles index the file's vertices: once a vertex was left out they no longer fit.
  Status onTriangles(const uint32_t* idx, size_t n) override {
    if (skipped_ > 0) {
      droppedTriangles_ += n;
      return Status::ok();
    }
    return next_.onTriangles(idx, n);
  }
  uint64_t droppedTriangles() const { return droppedTriangles_; }
  uint64_t skipped() const { return skipped_; }
  uint64_t read() const { return read_; }

 private:
  BatchSink& next_;
  const InputSet& in_;
  bool strict_;
  Progress& progress_;
  PointBatch keep_;
  uint64_t skipped_ = 0, read_ = 0, droppedTriangles_ = 0;
};

Status dracoOptions(const Args& a, DracoWriteOptions& dopt) {
  if (a.has("quantization")) {
    auto v = parseInt("quantization", a.get("quantization"), 0, 30);
    if (!v) return v.status();
    dopt.positionBits = int(*v);
  }
  if (a.has("normal-bits")) {
    auto v = parseInt("normal-bits", a.get("normal-bits"), 1, 30);
    if (!v) return v.status();
    dopt.normalBits = int(*v);
  }
  if (a.has("draco-speed")) {
    auto v = parseInt("draco-speed", a.get("draco-speed"), 0, 10);
    if (!v) return v.status();
    dopt.speed = int(*v);
  }
  return Status::ok();
}

// What a conversion wrote, for its summary.
struct Converted {
  uint64_t written = 0, bytes = 0, skipped = 0, read = 0, triangles = 0, inBytes = 0;
  bool shifted = false;  // Draco: positions relative to a recorded origin
  double seconds = 0;
};

Status writeDraco(const InputSet& input, const std::string& out, const DracoWriteOptions& dopt, bool strict, bool quiet,
                  Progress& progress, Converted& c) {
  DracoWriter w(dopt);
  Filter f(w, input, strict, progress);
  Status s = input.stream(f, input.hasTriangles());  // a single mesh input stays a mesh
  progress.finish();
  SA_RETURN_IF_ERROR(s);
  c.skipped = f.skipped();
  c.read = f.read();
  progress("encode", 0, 1);
  auto b = w.write(out, &c.shifted);
  progress.finish();
  if (!b) return b.status();
  c.bytes = *b;
  c.written = w.points();
  c.triangles = w.triangles();
  if (f.droppedTriangles() && !quiet)
    std::fprintf(stderr, "scanatlas: warning: %llu triangles left out: vertices with NaN coordinates were removed\n",
                 (unsigned long long)f.droppedTriangles());
  return Status::ok();
}

// name: what the error names when no point was finite (the first input as the user gave it).
Status writePointFile(const InputSet& input, const std::string& name, const std::string& out, const std::string& ext,
                      const PointLayout& layout, bool strict, Progress& progress, Converted& c) {
  auto w = ext == ".ply" ? openPlyWriter(out, layout) : openTextWriter(out, layout, ext == ".csv" ? ',' : ' ');
  if (!w) return w.status();
  Filter f(**w, input, strict, progress);
  Status s = input.stream(f, false);
  progress.finish();
  SA_RETURN_IF_ERROR(s);  // the writer's destructor removes its temporary file
  if (f.read() == f.skipped()) return Status::badInput(name + ": no finite points to write");
  SA_RETURN_IF_ERROR((*w)->finish());
  c.skipped = f.skipped();
  c.read = f.read();
  c.written = (*w)->written();
  auto b = fileSize(out);
  c.bytes = b ? *b : 0;
  return Status::ok();
}

std::string attributeList(const PointLayout& layout) {
  std::string attrs;
  auto add = [&](bool on, const char* n) {
    if (on) attrs += std::string(attrs.empty() ? "" : ",") + n;
  };
  add(layout.normals, "normals");
  add(layout.colors, "colors");
  add(layout.intensity, "intensity");
  add(layout.confidence, "confidence");
  add(layout.classification, "classification");
  return attrs;
}

void printJson(const std::string& out, const std::string& ext, const PointLayout& layout, const DracoWriteOptions& dopt,
               const Converted& c) {
  std::printf("{\"output\": \"%s\", \"format\": \"%s\", \"points\": %llu, \"read\": %llu, \"skipped_points\": %llu, "
              "\"bytes\": %llu, \"bytes_per_point\": %.3f, \"input_bytes\": %llu, \"attributes\": \"%s\", "
              "\"triangles\": %llu, \"quantization_bits\": %d, \"origin_shifted\": %s, \"seconds\": %.3f}\n",
              jsonEscape(out).c_str(), ext.c_str() + 1, (unsigned long long)c.written, (unsigned long long)c.read,
              (unsigned long long)c.skipped, (unsigned long long)c.bytes, double(c.bytes) / double(std::max<uint64_t>(1, c.written)),
              (unsigned long long)c.inBytes, attributeList(layout).c_str(), (unsigned long long)c.triangles,
              ext == ".drc" ? dopt.positionBits : -1, c.shifted ? "true" : "false", c.seconds);
}

void printSummary(const std::string& out, const std::string& ext, const PointLayout& layout, const DracoWriteOptions& dopt,
                  const Converted& c) {
  const std::string attrs = attributeList(layout);
  std::fprintf(stderr, "wrote %s: %llu points%s%s, %s%s\n  %.2f MiB (%.2f bytes/point; inputs %.2f MiB) in %.2fs\n",
               out.c_str(), (unsigned long long)c.written,
               c.skipped ? (" (" + std::to_string(c.skipped) + " NaN/Inf left out)").c_str() : "",
               c.triangles ? (", " + std::to_string(c.triangles) + " triangles").c_str() : "",
               attrs.empty() ? "positions only" : ("positions," + attrs).c_str(),
               ext == ".drc" ? (", Draco " + (dopt.positionBits ? std::to_string(dopt.positionBits) + "-bit positions"
                                                                : std::string("lossless positions")) +
                                (c.shifted ? ", relative to a recorded origin" : ""))
                                   .c_str()
                             : "",
               c.bytes / 1048576.0, double(c.bytes) / double(std::max<uint64_t>(1, c.written)), c.inBytes / 1048576.0, c.seconds);
}

}  // namespace

int cmdConvert(int argc, char** argv) {
  Args a;
  Status s = a.parse(argc, argv, {"output", "columns", "quantization", "normal-bits", "draco-speed"},
                     {"strict", "json", "quiet", "help"}, {{"o", "output"}, {"q", "quiet"}, {"h", "help"}});
  if (a.flag("help")) {
    std::fputs(kHelp, stdout);
    return 0;
  }
  if (!s) return reportError(s);
  if (a.positionals().empty()) return reportError(Status::badInput("convert: no input files (see --help)"));
  if (!a.has("output")) return reportError(Status::badInput("convert: -o OUT.{ply,drc,xyz,txt,csv} is required"));
  const std::string out = a.get("output");
  const std::string ext = lowerExtension(out);
  if (ext != ".ply" && ext != ".drc" && ext != ".xyz" && ext != ".txt" && ext != ".csv")
    return reportError(Status::badInput(out + ": unknown output format '" + ext + "' (use .ply, .drc, .xyz, .txt or .csv)"));
  if (std::filesystem::is_directory(out)) return reportError(Status::badInput(out + ": is a directory; give a file name"));
  DracoWriteOptions dopt;
  s = dracoOptions(a, dopt);
  if (!s) return reportError(s);
  auto input = InputSet::open(a.positionals(), a.get("columns"));
  if (input) {
    Status used = checkNotAnInput(out, input->allPaths(), "-o");
    if (!used) return reportError(used);
  }
  if (!input) return reportError(input.status());
  for (const auto& in : input->sourcePaths()) {
    std::error_code ec;
    if (std::filesystem::equivalent(in, out, ec))
      return reportError(Status::badInput(out + ": the output would overwrite an input"));
  }
  const bool quiet = a.flag("quiet") || a.flag("json");
  for (const auto& w : input->warnings())
    if (!quiet) std::fprintf(stderr, "scanatlas: warning: %s\n", w.c_str());
  removeStaleTemporaries(directoryOf(out), std::filesystem::path(out).filename().string() + ".tmp-");

  PointLayout layout;
  layout.normals = input->allHaveNormals();
  layout.colors = input->anyHasColors();
  layout.intensity = input->allHaveIntensity();
  layout.confidence = input->allHaveConfidence();
  layout.classification = input->allHaveClassification();

  const auto t0 = std::chrono::steady_clock::now();
  Progress progress(!quiet, "convert");
  Converted c;
  s = ext == ".drc" ? writeDraco(*input, out, dopt, a.flag("strict"), quiet, progress, c)
                    : writePointFile(*input, a.positionals()[0], out, ext, layout, a.flag("strict"), progress, c);
  if (!s) return reportError(s);
  c.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  for (const auto& f : input->files()) {
    auto b = fileSize(f.path);
    if (b) c.inBytes += *b;
  }
  if (a.flag("json")) printJson(out, ext, layout, dopt, c);
  else if (!a.flag("quiet")) printSummary(out, ext, layout, dopt, c);
  return 0;
}

}  // namespace sa
