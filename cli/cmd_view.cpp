#include <cstdio>
#include <filesystem>

#include "cli/args.h"
#include "cli/commands.h"
#include "cli/progress.h"
#include "cli/view_setup.h"
#include "common/fileio.h"
#include "preprocess/pipeline.h"
#include "window/viewer_app.h"

namespace sa {
namespace {

// A scan given to view is packed into SCAN.hfa beside it (reused while the input and the
// options are unchanged), with pack's progress bar and summary line.
Result<std::string> packForView(const std::string& path, bool quiet) {
  auto input = InputSet::open({path});
  if (!input) return input.status();
  const std::string cache =
      (std::filesystem::path(path).parent_path() / (std::filesystem::path(path).stem().string() + ".hfa")).string();
  SA_RETURN_IF_ERROR(checkNotAnInput(cache, input->allPaths(), "the view cache"));
  PackOptions po;
  po.commandLine = "view " + path;
  if (!quiet) std::fprintf(stderr, "view: packing %s into %s\n", path.c_str(), cache.c_str());
  Progress progress(!quiet, "view");
  PackSummary sum;
  Status s = packInput(*input, cache, po, [&](const char* p, uint64_t d, uint64_t t) { progress(p, d, t); }, sum);
  progress.finish();
  SA_RETURN_IF_ERROR(s);
  if (!quiet && sum.upToDate) std::fprintf(stderr, "view: %s is up to date\n", cache.c_str());
  if (!quiet && !sum.upToDate)
    std::fprintf(stderr, "view: packed %llu points into %u cells, %.1f MiB, in %.1f s\n", (unsigned long long)sum.pointsRead,
                 sum.cells, sum.fileBytes / 1048576.0, sum.seconds[5]);
  return cache;
}

}  // namespace

int cmdView(int argc, char** argv) {
  Args a;
  Status s = a.parse(argc, argv, {"script", "measurements", "size", "grooves", "gpu-budget"}, {"no-vsync", "quiet", "help"},
                     {{"q", "quiet"}, {"h", "help"}});
  if (a.flag("help")) {
    std::printf(
        "usage: scanatlas view PACK.hfa | SCAN [options]   (SCAN: any input pack reads)\n"
        "\n"
        "The interactive window: orbit, pan, zoom to cursor, fly, pick and measure, clip box and\n"
        "section plane, shading modes with eye-dome lighting, the cell-box view, bookmarks and\n"
        "screenshots. A scan (not a pack) is packed first into a cache beside it (SCAN.hfa, reused\n"
        "while the input and options are unchanged). Press H in the window for the keys.\n"
        "\n"
        "options:\n"
        "  --size WxH             window size (default 1280x800)\n"
        "  --no-vsync             render as fast as possible\n"
        "  --script FILE          replay a session (below), then close\n"
        "  --measurements FILE    picks and measurements as CSV (default: stdout)\n"
        "  --grooves FILE         a grooves JSON (scanatlas grooves): listed in the panel with width,\n"
        "                         depth and length (click to fly there) and drawn over the view\n"
        "%s"
        "\n%s",
        kGpuBudgetHelp, kViewerScriptHelp);
    return 0;
  }
  if (!s) return reportError(s);
  if (a.positionals().size() != 1) return reportError(Status::badInput("view: give one pack or scan (see --help)"));
  ViewerOptions opt;
  opt.scriptPath = a.get("script");
  opt.measurementsPath = a.get("measurements");
  opt.groovesPath = a.get("grooves");
  opt.vsync = !a.flag("no-vsync");
  opt.quiet = a.flag("quiet");
  if (a.has("size")) {
    s = parseWxH("size", a.get("size"), opt.width, opt.height);
    if (!s) return reportError(s);
  }
  std::string path = a.positionals()[0];
  if (lowerExtension(path) != ".hfa") {
    auto cache = packForView(path, opt.quiet);
    if (!cache) return reportError(cache.status());
    path = *cache;
  }
  auto budget = gpuBudgetFor(a, path);
  if (!budget) return reportError(budget.status());
  opt.gpuBudget = *budget;
  return runViewer(path, opt);
}

}  // namespace sa
