#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <cstring>
#include <sstream>

#include "atlas/pack_file.h"
#include "cli/args.h"
#include "cli/commands.h"
#include "cli/view_setup.h"
#include "common/fileio.h"
#include "viewer/egl_context.h"
#include "viewer/eval.h"
#include "viewer/renderer.h"
#include "viewer/source_points.h"

namespace sa {

const char* embeddedScript(std::string_view name);

namespace {

const char* kHelp =
    "usage: scanatlas eval PACK --reference MESH.ply|SCANS.conf [--path cams.json | --orbit N] [options]\n"
    "\n"
    "Image error against a reference render of the original data, with the same cameras: the\n"
    "reference's triangles rasterized on the CPU in double precision (a mesh PLY, or a Stanford\n"
    "scan set whose range grids are triangulated: neighbouring grid samples, edges longer than\n"
    "--max-edge dropped). Per view and per configuration: coverage IoU, silhouette error\n"
    "(pixels whose coverage differs / reference silhouette perimeter), depth error median and\n"
    "p95 relative to the bounding-box diagonal, normal angular error median, PSNR of the shaded\n"
    "image (both shaded alike: Lambert, head light, no scan colour), and the frame time.\n"
    "\n"
    "options:\n"
    "  --reference FILE       the ground truth (required)\n"
    "  --max-edge X           scan sets: longest grid triangle edge kept (default 3 x median)\n"
    "  --path FILE | --orbit N   cameras (default --orbit 8); --zoom F as for bench\n"
    "  --size WxH             (default 1024x1024); --fov DEG, --up X,Y,Z as for render\n"
    "  --mode LIST            parallax, points (default parallax)\n"
    "  --iterations LIST      parallax step bounds (default 12)\n"
    "  --repeat N             timed rounds over all views, after one warm-up round (median per\n"
    "                         view; default 3)\n"
    "  --csv FILE             one row per view and configuration plus 'all' summary rows\n"
    "  --plot FILE.png        run time vs error plot (also FILE.svg); needs python3-matplotlib\n"
    "  --json                 summary as JSON on stdout\n"
    "  -q, --quiet            no table\n";

struct Row {
  std::string mode, skips;
  int iterations = 0;
  double frameMs = 0, iou = 0, iouMin = 1, sil = 0, depthMed = 0, depthP95 = 0, normalMed = -1, psnr = 0;
};

}  // namespace

int cmdEval(int argc, char** argv) {
  Args a;
  Status s = a.parse(argc, argv,
                     {"reference", "max-edge", "path", "orbit", "zoom", "size", "fov", "up", "mode", "iterations", "repeat",
                      "csv", "plot"},
                     {"json", "quiet", "help"}, {{"q", "quiet"}, {"h", "help"}});
  if (a.flag("help")) {
    std::fputs(kHelp, stdout);
    return 0;
  }
  if (!s) return reportError(s);
  if (a.positionals().size() != 1) return reportError(Status::badInput("eval: give exactly one pack (see --help)"));
  if (!a.has("reference")) return reportError(Status::badInput("eval: --reference MESH.ply|SCANS.conf is required"));
  PackReader pack;
  s = pack.open(a.positionals()[0]);
  if (!s) return reportError(s);
  std::vector<Camera> cams;
  s = camerasFromArgs(a, pack, 8, 1024, cams);
  if (!s) return reportError(s);
  double maxEdge = 0;
  if (a.has("max-edge")) {
    auto v = parseNumber("max-edge", a.get("max-edge"));
    if (!v) return reportError(v.status());
    maxEdge = *v;
  }
  auto repeat = parseInt("repeat", a.get("repeat", "3"), 1, 1000);
  if (!repeat) return reportError(repeat.status());
  std::vector<RenderMode> modes;
  std::vector<int> iters;
  s = modesAndIterations(a, modes, iters);
  if (!s) return reportError(s);
  if (a.has("plot")) {
    // Check the plotting dependency before the long part.
    if (std::system("/usr/bin/python3 -c 'import matplotlib' >/dev/null 2>&1") != 0)
      return reportError(Status::badInput("--plot needs Debian's python3-matplotlib: apt-get install python3-matplotlib"));
  }
  const bool quiet = a.flag("quiet") || a.flag("json");
  auto ref = loadReference(a.get("reference"), maxEdge);
  if (!ref) return reportError(ref.status());
  if (!quiet) std::fprintf(stderr, "eval: reference %s\n", ref->description.c_str());
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (size_t i = 0; i < ref->positions.size(); i += 3) {
    lo = lo.cwiseMin(Eigen::Vector3d(&ref->positions[i]));
    hi = hi.cwiseMax(Eigen::Vector3d(&ref->positions[i]));
  }
  const double diag = (hi - lo).norm();
  RenderSettings base;
  base.useColor = false;  // both images shaded alike
  std::vector<ReferenceView> views;
  std::vector<Image> shaded;
  for (const Camera& c : cams) {
    views.push_back(referenceView(*ref, c));
    shaded.push_back(shadeReference(views.back(), c, base.baseColor, base.background));
  }

  EglContext ctx;
  s = ctx.init();
  if (!s) return reportError(s);
  Renderer renderer;
  s = renderer.init(pack);
  if (!s) return reportError(s);
  if (std::find(modes.begin(), modes.end(), RenderMode::kPoints) != modes.end()) {
    s = uploadSourcePoints(pack, renderer);
    if (!s) return reportError(s);
  }
  std::ostringstream csv;
  csv << "pack,mode,iterations,skips,view,frame_ms,iou,silhouette_error,depth_median,depth_p95,normal_median_deg,psnr\n";
  std::vector<Row> rows;
  for (RenderMode mode : modes) {
    const std::vector<int> its = mode == RenderMode::kPoints ? std::vector<int>{0} : iters;
    for (int it : its) {
      RenderSettings rs = base;
      rs.mode = mode;
      if (it > 0) rs.iterations = it;
      Row row;
      row.mode = modeName(mode);
      row.iterations = it;
      row.skips = mode == RenderMode::kPoints ? "-" : "all";
      // Timing first, the way bench times: the views cycled back to back without read-back
      // (llvmpipe's point rendering runs up to 3x faster right after a full read-back, which
      // a frame shown on screen never gets).
      std::vector<std::vector<double>> perView(cams.size());
      for (int64_t r = 0; r < *repeat + 1; ++r) {
        for (size_t v = 0; v < cams.size(); ++v) {
          FrameResult tr;
          s = renderer.render(cams[v], rs, tr, 0u);
          if (!s) return reportError(s);
          if (r > 0) perView[v].push_back(tr.stats.cpuMs);  // the first round warms up
        }
      }
      std::vector<double> times, depthAll, normalAll;
      double psnrSum = 0, iouSum = 0, silSum = 0;
      for (size_t v = 0; v < cams.size(); ++v) {
        FrameResult fr;
        s = renderer.render(cams[v], rs, fr, kReadColor | kReadDepth | (mode == RenderMode::kParallax ? kReadNormals : 0u));
        if (!s) return reportError(s);
        const double ms = percentile(perView[v], 0.5);
        times.push_back(ms);
        ViewMetrics m = evaluateView(fr.color, fr.depth, fr.normals, views[v], shaded[v], diag);
        depthAll.insert(depthAll.end(), m.depthErrors.begin(), m.depthErrors.end());
        normalAll.insert(normalAll.end(), m.normalErrors.begin(), m.normalErrors.end());
        psnrSum += m.psnr;
        iouSum += m.iou;
        silSum += m.silhouetteError;
        row.iouMin = std::min(row.iouMin, m.iou);
        csv << jsonEscape(pack.path()) << "," << row.mode << "," << it << "," << row.skips << "," << v << "," << ms << ","
            << m.iou << "," << m.silhouetteError << "," << m.depthMedian << "," << m.depthP95 << "," << m.normalMedianDeg
            << "," << m.psnr << "\n";
      }
      const double n = double(cams.size());
      row.frameMs = percentile(times, 0.5);
      row.iou = iouSum / n;
      row.sil = silSum / n;
      row.psnr = psnrSum / n;
      row.depthMed = percentile(depthAll, 0.5);
      row.depthP95 = percentile(depthAll, 0.95);
      row.normalMed = normalAll.empty() ? -1 : percentile(normalAll, 0.5);
      csv << jsonEscape(pack.path()) << "," << row.mode << "," << it << "," << row.skips << ",all," << row.frameMs << ","
          << row.iou << "," << row.sil << "," << row.depthMed << "," << row.depthP95 << "," << row.normalMed << ","
          << row.psnr << "\n";
      rows.push_back(row);
    }
  }
  if (!quiet) {
    std::fprintf(stderr, "%-9s %5s %10s %8s %8s %8s %12s %12s %10s %8s\n", "mode", "iters", "frame ms", "IoU",
                 "IoU min", "silh.", "depth med %", "depth p95 %", "normal deg", "PSNR dB");
    for (const Row& r : rows)
      std::fprintf(stderr, "%-9s %5s %10.2f %8.4f %8.4f %8.3f %12.5f %12.4f %10s %8.2f\n", r.mode.c_str(),
                   r.iterations ? std::to_string(r.iterations).c_str() : "-", r.frameMs, r.iou, r.iouMin, r.sil,
                   100 * r.depthMed, 100 * r.depthP95,
                   r.normalMed < 0 ? "-" : std::to_string(r.normalMed).substr(0, 6).c_str(), r.psnr);
    std::fprintf(stderr, "renderer: %s; %zu view(s) at %dx%d; errors relative to the reference diagonal %.6g\n",
                 ctx.renderer().c_str(), cams.size(), cams[0].width, cams[0].height, diag);
  }
  if (a.flag("json")) {
    std::printf("{\"pack\": \"%s\", \"reference\": \"%s\", \"renderer\": \"%s\", \"views\": %zu, \"width\": %d, "
                "\"height\": %d, \"diagonal\": %.9g, \"configs\": [",
                jsonEscape(pack.path()).c_str(), jsonEscape(ref->description).c_str(), jsonEscape(ctx.renderer()).c_str(),
                cams.size(), cams[0].width, cams[0].height, diag);
    for (size_t i = 0; i < rows.size(); ++i) {
      const Row& r = rows[i];
      std::printf("%s{\"mode\": \"%s\", \"iterations\": %d, \"frame_ms\": %.4f, \"iou\": %.6f, \"iou_min\": %.6f, "
                  "\"silhouette_error\": %.6f, \"depth_median\": %.8g, \"depth_p95\": %.8g, \"normal_median_deg\": %s, "
                  "\"psnr\": %.4f}",
                  i ? ", " : "", r.mode.c_str(), r.iterations, r.frameMs, r.iou, r.iouMin, r.sil, r.depthMed, r.depthP95,
                  r.normalMed < 0 ? "null" : std::to_string(r.normalMed).c_str(), r.psnr);
    }
    std::printf("]}\n");
  }
  const std::string text = csv.str();
  if (a.has("csv")) {
    s = writeFileAtomic(a.get("csv"), text.data(), text.size());
    if (!s) return reportError(s);
  }
  if (a.has("plot")) {
    ScratchDir tmp;
    s = tmp.create(std::filesystem::temp_directory_path().string(), "scanatlas-plot-");
    if (!s) return reportError(s);
    const std::string csvPath = joinPath(tmp.path(), "summary.csv"), script = joinPath(tmp.path(), "plot.py");
    s = writeFileAtomic(csvPath, text.data(), text.size());
    if (!s) return reportError(s);
    const char* py = embeddedScript("plot_tradeoff.py");
    s = writeFileAtomic(script, py, std::strlen(py));
    if (!s) return reportError(s);
    const std::string cmd = "/usr/bin/python3 '" + script + "' '" + csvPath + "' '" + a.get("plot") + "'";
    if (std::system(cmd.c_str()) != 0) return reportError(Status::internal("plotting failed: " + cmd));
    if (!quiet) std::fprintf(stderr, "eval: wrote %s and its .svg\n", a.get("plot").c_str());
  }
  return 0;
}

}  // namespace sa
