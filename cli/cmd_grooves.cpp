// `scanatlas grooves`: detect cracks and joints in a scan's raw points and export them.
#include <chrono>
#include <cstdio>
#include <filesystem>

#include "atlas/pack_file.h"
#include "cli/args.h"
#include "cli/commands.h"
#include "common/fileio.h"
#include "formats/source.h"
#include "grooves/grooves.h"

namespace sa {
namespace {

constexpr const char* kHelp =
    "usage: scanatlas grooves INPUT... [--json FILE] [--csv FILE] [options]\n"
    "       scanatlas grooves PACK.hfa [...]   (the files the pack was made from)\n\n"
    "Finds grooves (cracks, joints, engraved lines) in the input's raw points: in regions of\n"
    "--region spacings, each over its own plane, the residual against a robust low-pass, valleys\n"
    "of its Hessian at 0.75-4 spacings (strength measured against the region's own noise),\n"
    "sub-spacing centre lines linked with hysteresis, and a V or U profile fitted to the points\n"
    "across each line (width, depth below the rim). Thin elongated strips with no points (deep\n"
    "cracks return none) are reported as shape \"gap\" with an unknown depth. Lines are joined\n"
    "across regions and crossings in world coordinates. Widths are uncertain by one sample spacing;\n"
    "cracks narrower than about 1.5 spacings are not in the data.\n\n"
    "  --json FILE          every groove: polyline, width, depth, length, confidence, profile (editable)\n"
    "  --csv FILE           one row per groove; the polyline as 'x y z;x y z;...'\n"
    "  --grooves FILE       measure these grooves (a grooves JSON: edited, or polylines drawn by\n"
    "                       hand; only \"polyline\" and \"width\" are needed) instead of detecting:\n"
    "                       width, depth, shape and profile from the points across each line, the\n"
    "                       line lifted onto the rim; a line with too few points beside it is kept\n"
    "                       as given\n"
    "  --spacing S          sample spacing in input units (default: measured)\n"
    "  --min-width W        narrowest groove looked for, in spacings (default 1.5)\n"
    "  --max-width W        widest, in spacings (default 8)\n"
    "  --min-length L       shorter lines are dropped, in spacings (default 6)\n"
    "  --threshold T        valley strength over the noise that starts a line (default 5)\n"
    "  --low-threshold T    ... that continues one (default 3)\n"
    "  --region R           region side in spacings (default 64)\n"
    "  --no-gaps            do not report uncovered strips (always off for a mesh: its triangles\n"
    "                       cover the strips between its vertices)\n"
    "  --quiet              no progress\n";

struct PointSink : BatchSink {
  std::vector<double> pos;
  Status onPoints(const PointBatch& b) override {
    for (size_t i = 0; i < b.size(); ++i) pos.insert(pos.end(), {b.x[i], b.y[i], b.z[i]});
    return Status::ok();
  }
};

Status readOptions(const Args& a, GrooveOptions& o) {
  struct Num {
    const char* name;
    double* out;
    double lo;
  } nums[] = {{"spacing", &o.spacing, 0},        {"min-width", &o.minWidth, 0.5}, {"max-width", &o.maxWidth, 1},
              {"min-length", &o.minLength, 0},   {"threshold", &o.threshold, 0},  {"low-threshold", &o.lowThreshold, 0},
              {"region", &o.region, 16}};
  for (const Num& n : nums) {
    if (!a.has(n.name)) continue;
    Result<double> v = parseNumber(n.name, a.get(n.name));
    if (!v) return v.status();
    if (!(*v > n.lo) && !(*v == n.lo && n.lo == 0))
      return Status::badInput(std::string("--") + n.name + " must be above " + std::to_string(n.lo));
    *n.out = *v;
  }
  if (o.minWidth > o.maxWidth) return Status::badInput("--min-width must not exceed --max-width");
  if (o.lowThreshold > o.threshold) return Status::badInput("--low-threshold must not exceed --threshold");
  o.gaps = !a.flag("no-gaps");
  return Status::ok();
}

void printSummary(const GrooveSet& set, double seconds) {
  std::printf("%zu groove%s, %.6g long in all (spacing %.4g, noise %.4g; %u regions, %u not a height field) in %.1f s\n",
              set.grooves.size(), set.grooves.size() == 1 ? "" : "s", set.totalLength(), set.spacing, set.noise,
              set.regions, set.skippedRegions, seconds);
  const size_t show = std::min<size_t>(set.grooves.size(), 20);
  if (show) std::printf("  %4s %5s %10s %10s %10s %5s\n", "id", "shape", "width", "depth", "length", "conf");
  for (size_t i = 0; i < show; ++i) {
    const Groove& g = set.grooves[i];
    std::printf("  %4zu %5s %10.4g ", i, g.shape.c_str(), g.width);
    if (g.shape == "gap") std::printf("%10s", "?");
    else std::printf("%10.4g", g.depth);
    std::printf(" %10.4g %5.2f\n", g.length, g.confidence);
  }
  if (show < set.grooves.size()) std::printf("  ... %zu more in the files\n", set.grooves.size() - show);
}

// A pack names the files it was made from: grooves are found in their raw points.
Status packInputs(std::vector<std::string>& inputs, std::string& columns) {
  if (inputs.size() != 1 || lowerExtension(inputs[0]) != ".hfa") return Status::ok();
  PackReader pack;
  SA_RETURN_IF_ERROR(pack.open(inputs[0]));
  std::vector<std::string> sources = packSources(pack, columns);
  if (sources.empty()) return Status::badInput(inputs[0] + ": the pack names no source files; grooves are found in the raw points");
  for (const std::string& f : sources)
    if (!std::filesystem::exists(f))
      return Status::badInput(inputs[0] + ": source file " + f + " is gone; grooves are found in the raw points");
  std::fprintf(stderr, "grooves: %s: reading its %zu source file%s\n", inputs[0].c_str(), sources.size(),
               sources.size() == 1 ? "" : "s");
  inputs = std::move(sources);
  return Status::ok();
}

}  // namespace

int cmdGrooves(int argc, char** argv) {
  Args a;
  Status s = a.parse(argc, argv,
                     {"json", "csv", "grooves", "spacing", "min-width", "max-width", "min-length", "threshold",
                      "low-threshold", "region"},
                     {"no-gaps", "quiet", "help"}, {{"h", "help"}});
  if (a.flag("help")) {
    std::fputs(kHelp, stdout);
    return 0;
  }
  if (!s) return reportError(s);
  if (a.positionals().empty()) return reportError(Status::badInput("grooves: name at least one input (see --help)"));
  GrooveOptions opt;
  s = readOptions(a, opt);
  if (!s) return reportError(s);
  std::vector<std::string> inputs = a.positionals();
  std::string columns;
  s = packInputs(inputs, columns);
  if (!s) return reportError(s);
  Result<InputSet> input = InputSet::open(inputs, columns);
  if (!input) return reportError(input.status());
  std::vector<std::string> reads = input->allPaths();
  reads.insert(reads.end(), a.positionals().begin(), a.positionals().end());
  for (const char* out : {"json", "csv"})
    if (a.has(out)) {
      s = checkNotAnInput(a.get(out), reads, std::string("--") + out);
      if (!s) return reportError(s);
    }
  const auto t0 = std::chrono::steady_clock::now();
  PointSink sink;
  s = input->stream(sink, false);
  if (!s) return reportError(s);
  if (sink.pos.size() < 3 * 64) return reportError(Status::badInput("grooves: the input holds fewer than 64 points"));
  // A mesh's triangles cover the strips between its vertices: no strip is a hole in the data.
  if (input->hasTriangles() && opt.gaps) {
    opt.gaps = false;
    std::fprintf(stderr, "grooves: %s is a mesh: uncovered strips are not reported (its triangles cover them)\n",
                 input->files()[0].path.c_str());
  }
  const bool quiet = a.flag("quiet");
  if (!quiet)
    opt.progress = [](uint64_t d, uint64_t t) {
      if (d == t || d % 64 == 0) std::fprintf(stderr, "\rgrooves: region %llu / %llu", (unsigned long long)d, (unsigned long long)t);
      if (d == t) std::fprintf(stderr, "\n");
    };
  GrooveSet set;
  if (a.has("grooves")) {
    Result<GrooveSet> given = readGroovesJson(a.get("grooves"));
    if (!given) return reportError(given.status());
    set = measureGrooves(sink.pos.data(), sink.pos.size() / 3, *given, opt);
    std::fprintf(stderr, "grooves: measured %zu given groove%s from %s", set.grooves.size() - set.unmeasured,
                 set.grooves.size() - set.unmeasured == 1 ? "" : "s", a.get("grooves").c_str());
    if (set.unmeasured) std::fprintf(stderr, "; %u with too few points beside them kept as given", set.unmeasured);
    std::fprintf(stderr, "\n");
  } else {
    set = detectGrooves(sink.pos.data(), sink.pos.size() / 3, opt);
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (a.has("json") && !(s = writeGroovesJson(set, a.get("json")))) return reportError(s);
  if (a.has("csv") && !(s = writeGroovesCsv(set, a.get("csv")))) return reportError(s);
  printSummary(set, secs);
  return 0;
}

}  // namespace sa
