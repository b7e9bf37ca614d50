#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <sstream>

#include "atlas/pack_file.h"
#include "cli/args.h"
#include "cli/commands.h"
#include "modes/registry.h"
#include "cli/progress.h"
#include "cli/view_setup.h"
#include "common/fileio.h"
#include "viewer/egl_context.h"
#include "viewer/eval.h"
#include "viewer/renderer.h"
#include "viewer/source_points.h"

namespace sa {
namespace {

const char* kHelp =
    "usage: scanatlas bench PACK [--path cams.json | --orbit N] [options]\n"
    "\n"
    "Batch frame-time measurement, headless (EGL): every combination of --mode and\n"
    "--iterations renders the camera path (cycled to --frames frames after --warmup frames).\n"
    "Per frame: GPU time (GL_TIME_ELAPSED around the draws), CPU wall time (culling, submission\n"
    "and glFinish), boxes submitted / culled / drawn / splatted, fragments shaded.\n"
    "\n"
    "options:\n"
    "  --path FILE            camera path JSON ({\"cameras\": [{\"eye\", \"target\", \"up\", \"fov\"}, ...]})\n"
    "  --orbit N              N cameras around the bounding box (default 60)\n"
    "  --zoom F               orbit cameras F times closer (F > 1: close-ups, frustum culling\n"
    "                         matters; F < 1: far away, boxes shrink below a pixel)\n"
    "  --size WxH             frame size (default 1024x1024)\n"
    "  --fov DEG, --up X,Y,Z  for --orbit (defaults 40 and the pack's up axis)\n"
    "  --warmup N             frames rendered before timing each configuration (default 10)\n"
    "  --frames N             timed frames per configuration (default 200)\n"
    "  --mode LIST            parallax, exact, vdm, gdm, slices, auto, grooves, points (default parallax).\n"
    "                         exact, vdm, gdm and grooves need their section ('scanatlas bake PACK --mode M'); without\n"
    "                         it the mode's fallback is drawn and said. points: the source points\n"
    "                         as splats (reads the pack's source files). Per mode: its bytes on the\n"
    "                         GPU and on disk, bake seconds, and the work per ray (parallax: height\n"
    "                         samples; the others: pyramid nodes, voxels; vdm, gdm: lookups and\n"
    "                         fallbacks) from one counted pass over the cameras after the timed frames\n"
    "  --iterations LIST      ray-march step bounds for parallax (default 64)\n"
    "  --slices N|auto        slices mode: quads per cell (default 16; auto: from each cell's distance)\n"
    "  --gdm-elsewhere M      gdm mode: how the cells that are height fields are drawn, exact (the\n"
    "                         default) or parallax (--iterations): then gdm differs from parallax\n"
    "                         only where it draws a forced cell's surface\n"
    "  --auto-pixels P        auto mode: boxes under P pixels across are drawn as slices, a pixel\n"
    "                         apart along the view (depth error <= sqrt(3) pixels); the others by\n"
    "                         the parallax march (default 8)\n"
    "  --compare-skips        also run parallax with each skip turned off, one at a time, and the\n"
    "                         auto mode (small boxes as slices) to show what that switch saves\n"
    "  --interleave           run the configurations frame by frame in turn instead of one after\n"
    "                         the other: a drift of the machine's speed then falls on all of them\n"
    "                         alike, so their ratios hold (use it to compare modes on a shared or\n"
    "                         software renderer)\n"
    "  --no-groove-aa         grooves mode: one ray a pixel also where a groove is under 2 pixels wide\n"
    "  --no-color             ignore scan colours (as eval does)\n"
    "  --no-frustum-cull, --no-backface-cull, --no-adaptive-steps, --no-splats, --no-sort\n"
    "                         turn a skip off for every configuration\n"
    "  --stream               open the pack as the window does (tiles decoded in the background,\n"
    "                         the visible ones nearest the camera first) and report the time to the\n"
    "                         first frame and to the first frame that lacks no visible cell, on the\n"
    "                         first camera; the timed frames then run with every tile resident\n"
    "%s"
    "                         (bench: per configuration the uploads, evictions, cells drawn coarser\n"
    "                         and bytes resident per frame; the timed frames stream as they would)\n"
    "  --budget-error         with --gpu-budget: after the timed frames, each camera's view once it\n"
    "                         has settled (no tile pending) against the same view with every tile\n"
    "                         resident (a second renderer: needs the whole atlas in GPU memory and\n"
    "                         RAM): coverage IoU and depth error in texels, per view and overall\n"
    "  --csv FILE             one row per frame\n"
    "  --json                 the summary as JSON on stdout\n"
    "  -q, --quiet            no table\n";

struct Config {
  RenderSettings settings;
  std::string skips = "all";
};

struct Summary {
  double median = 0, p95 = 0, p99 = 0, min = 0, max = 0, mean = 0;
};

Summary summarize(std::vector<double> v) {
  Summary s;
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  auto q = [&](double f) { return v[std::min(v.size() - 1, size_t(f * double(v.size() - 1) + 0.5))]; };
  s.median = q(0.5);
  s.p95 = q(0.95);
  s.p99 = q(0.99);
  s.min = v.front();
  s.max = v.back();
  for (double x : v) s.mean += x;
  s.mean /= double(v.size());
  return s;
}

std::string summaryJson(const Summary& s) {
  char b[256];
  std::snprintf(b, sizeof(b), "{\"median\": %.4f, \"p95\": %.4f, \"p99\": %.4f, \"min\": %.4f, \"max\": %.4f, \"mean\": %.4f}",
                s.median, s.p95, s.p99, s.min, s.max, s.mean);
  return b;
}

// One configuration's frames and what they measured.
struct Row {
  Config config;
  std::vector<double> gpuMs, cpuMs;  // per timed frame
  Summary gpu, cpu;
  double drawn = 0, culled = 0, splats = 0, sliced = 0, frags = 0, submitted = 0;
  double uploads = 0, evicted = 0, coarsened = 0, missing = 0, residentBytes = 0, heldBytes = 0;  // --gpu-budget, per frame
  double deferred = 0, undeferred = 0;  // grooves: pixels left to the carved cast, and without a slot, per frame
  bool invocations = false;
  WorkCounters work;  // one counted frame per camera, after the timed ones (atomics cost time)
  RenderMode drawn_mode = RenderMode::kParallax;
};

// Frame f of a configuration (the cameras cycled), untimed.
Status warmFrame(Renderer& renderer, const std::vector<Camera>& cams, const Config& c, int64_t f) {
  FrameResult fr;
  return renderer.render(cams[size_t(f) % cams.size()], c.settings, fr, 0u);
}

// Timed frame f of configuration ci: its times and counts added to the row, a CSV line.
Status timedFrame(Renderer& renderer, const std::vector<Camera>& cams, size_t ci, int64_t f, std::ostringstream& csv, Row& row) {
  const Config& c = row.config;
  const size_t cam = size_t(f) % cams.size();
  FrameResult fr;
  SA_RETURN_IF_ERROR(renderer.render(cams[cam], c.settings, fr, 0u));
  const FrameStats& st = fr.stats;
  row.gpuMs.push_back(st.gpuMs);
  row.cpuMs.push_back(st.cpuMs);
  row.drawn += st.drawn;
  row.culled += st.culled;
  row.splats += st.splats;
  row.sliced += st.sliced;
  row.frags += double(st.fragments);
  row.submitted += st.submitted;
  row.uploads += st.uploads;
  row.evicted += st.evicted;
  row.coarsened += st.coarsened;
  row.missing += st.missing;
  row.residentBytes += double(st.residentBytes);
  row.heldBytes += double(st.heldBytes);
  row.deferred += double(st.deferred);
  row.undeferred += double(st.undeferred);
  row.invocations = st.fragmentsAreInvocations;
  row.drawn_mode = st.drawnMode;
  csv << ci << "," << modeName(c.settings.mode) << "," << c.settings.iterations << "," << c.skips << "," << f << ","
      << cam << "," << st.gpuMs << "," << st.cpuMs << "," << st.submitted << "," << st.culled << "," << st.drawn << ","
      << st.inside << "," << st.splats << "," << st.points << "," << st.fragments << "\n";
  return Status::ok();
}

// After the timed frames: per-frame means, the time summaries, and one counted frame per camera.
Status finishRow(Renderer& renderer, const std::vector<Camera>& cams, Row& row) {
  const double n = double(std::max<size_t>(row.cpuMs.size(), 1));
  for (double* v : {&row.drawn, &row.culled, &row.splats, &row.sliced, &row.frags, &row.submitted, &row.uploads, &row.evicted,
                    &row.coarsened, &row.missing, &row.residentBytes, &row.heldBytes, &row.deferred, &row.undeferred})
    *v /= n;
  row.gpu = summarize(row.gpuMs);
  row.cpu = summarize(row.cpuMs);
  if (row.config.settings.mode == RenderMode::kPoints) return Status::ok();
  RenderSettings counted = row.config.settings;
  counted.countWork = true;
  FrameResult fr;
  for (const Camera& cam : cams) {
    SA_RETURN_IF_ERROR(renderer.render(cam, counted, fr, 0u));
    row.work.add(fr.stats.work);
  }
  return Status::ok();
}

std::string rowJson(const Row& r, const Renderer& renderer, const PackReader& pack, bool budget) {
  const Config& c = r.config;
  const bool points = c.settings.mode == RenderMode::kPoints;
  const ModeSection ms = modeSection(pack, c.settings.mode);
  std::ostringstream json;
  json << "{\"mode\": \"" << modeName(c.settings.mode) << "\", \"iterations\": " << (points ? 0 : c.settings.iterations)
       << ", \"skips\": \"" << c.skips << "\", \"gpu_ms\": " << summaryJson(r.gpu) << ", \"cpu_ms\": " << summaryJson(r.cpu)
       << ", \"fps\": " << 1000.0 / std::max(r.cpu.median, 1e-9) << ", \"boxes_submitted\": " << r.submitted
       << ", \"boxes_culled\": " << r.culled << ", \"boxes_drawn\": " << r.drawn << ", \"splats\": " << r.splats << ", \"sliced\": " << r.sliced
       << ", \"fragments\": " << r.frags << ", \"fragments_are_invocations\": " << (r.invocations ? "true" : "false")
       << ", \"atlas_bytes\": " << renderer.gpuBytes() << ", \"point_bytes\": " << (points ? renderer.pointBytes() : 0)
       << ", \"drawn_mode\": \"" << modeName(points ? RenderMode::kPoints : r.drawn_mode) << "\""
       << ", \"mode_gpu_bytes\": " << renderer.modeGpuBytes(c.settings.mode) << ", \"mode_disk_bytes\": " << ms.bytes
       << ", \"bake_s\": " << ms.bakeSeconds;
  if (r.drawn_mode == RenderMode::kGdm)
    json << ", \"gdm_elsewhere\": \"" << (c.settings.gdmParallaxElsewhere ? "parallax" : "exact") << "\"";
  if (r.drawn_mode == RenderMode::kGrooves)
    json << ", \"grooves\": {\"deferred_per_frame\": " << r.deferred << ", \"unslotted_per_frame\": " << r.undeferred << "}";
  if (budget)
    json << ", \"budget\": {\"uploads_per_frame\": " << r.uploads << ", \"evicted_per_frame\": " << r.evicted
         << ", \"coarsened_per_frame\": " << r.coarsened << ", \"missing_per_frame\": " << r.missing
         << ", \"resident_bytes\": " << r.residentBytes
         << ", \"held_bytes\": " << r.heldBytes << "}";
  if (r.work.valid && r.work.rays > 0)  // modes that cast nothing (slices) count nothing
    json << ", \"work\": {\"unit\": \"" << (r.drawn_mode == RenderMode::kParallax ? "samples" : "nodes") << "\", \"rays\": " << r.work.rays
         << ", \"lookups\": " << r.work.lookups << ", \"fallbacks\": " << r.work.fallbacks
         << ", \"fast_misses\": " << r.work.fastMisses
         << ", \"hits\": " << r.work.hits << ", \"mean\": " << r.work.mean() << ", \"p50\": " << r.work.p50 << ", \"p90\": "
         << r.work.p90 << ", \"p99\": " << r.work.p99 << ", \"max\": " << r.work.max << ", \"capped\": " << r.work.capped << "}";
  json << "}";
  return json.str();
}

// The frame time first (cpu: culling through glFinish); the GPU timer after it, with a note
// where it does not measure the frame (llvmpipe rasterizes after the timer query closes).
void printTable(const std::vector<Row>& rows, const std::string& renderer) {
  std::fprintf(stderr, "%-9s %5s %-18s %9s %9s %9s %9s %8s %9s %8s %8s %8s %12s %10s %8s\n", "mode", "iters", "skips", "frame med",
               "frame p95", "frame p99", "frame min", "fps", "gpu med", "drawn", "culled", "splats", "fragments", "work/ray", "work p99");
  for (const Row& r : rows) {
    const bool points = r.config.settings.mode == RenderMode::kPoints;
    const bool gdmParallax = r.drawn_mode == RenderMode::kGdm && r.config.settings.gdmParallaxElsewhere;
    const bool exactMode = r.drawn_mode != RenderMode::kParallax && !points && !gdmParallax;
    std::fprintf(stderr, "%-9s %5s %-18s %9.2f %9.2f %9.2f %9.2f %8.1f %9.2f %8.0f %8.0f %8.0f %12.0f %10.1f %8u\n",
                 gdmParallax ? "gdm+par" : modeName(points ? RenderMode::kPoints : r.drawn_mode),
                 points || exactMode ? "-" : std::to_string(r.config.settings.iterations).c_str(),
                 r.config.skips.c_str(), r.cpu.median, r.cpu.p95, r.cpu.p99, r.cpu.min, 1000.0 / std::max(r.cpu.median, 1e-9),
                 r.gpu.median, r.drawn, r.culled, r.splats, r.frags, r.work.mean(), r.work.p99);
  }
  if (renderer.find("llvmpipe") != std::string::npos)
    std::fprintf(stderr, "note: frame = CPU wall time through glFinish, the frame time. On llvmpipe 'gpu med' "
                         "(GL_TIME_ELAPSED) is not: llvmpipe rasterizes after the query closes.\n");
}

// --stream: the window's start on the first camera, times from before the pack was opened.
struct StreamReport {
  double openMs = 0, initMs = 0, firstFrameMs = 0, viewCompleteMs = 0;
  uint64_t frames = 0;
  uint32_t tilesResident = 0;
};

Status streamFirstView(Renderer& r, const Camera& cam, const RenderSettings& rs,
                       std::chrono::steady_clock::time_point t0, StreamReport& out) {
  auto ms = [&] { return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count(); };
  FrameResult fr;
  for (;;) {
    SA_RETURN_IF_ERROR(r.render(cam, rs, fr, 0u));
    if (out.frames++ == 0) out.firstFrameMs = ms();
    if (fr.stats.missing == 0) break;
  }
  out.viewCompleteMs = ms();
  out.tilesResident = r.tilesResident();
  r.waitForTiles();
  const std::string e = r.streamError();
  return e.empty() ? Status::ok() : Status::badInput(e);
}

std::string streamJson(const StreamReport& s, uint32_t cells) {
  char b[256];
  std::snprintf(b, sizeof b,
                "{\"open_ms\": %.1f, \"init_ms\": %.1f, \"first_frame_ms\": %.1f, \"view_complete_ms\": %.1f, \"frames_to_complete\": %llu, "
                "\"tiles_resident\": %u, \"tiles\": %u}",
                s.openMs, s.initMs, s.firstFrameMs, s.viewCompleteMs, (unsigned long long)s.frames, s.tilesResident, cells);
  return b;
}

// --budget-error: every camera's settled budget view against the same view with every tile
// resident, in the first configuration's settings.
struct BudgetError {
  double iouMean = 0, iouMin = 1, depthMedianMax = 0, depthP95Max = 0;
  uint64_t settleFrames = 0;  // most frames a view took to settle
  size_t views = 0;
};

Status measureBudgetError(Renderer& budgeted, const std::string& packPath, const std::vector<Camera>& cams,
                          RenderSettings rs, bool print, BudgetError& out) {
  rs.mode = budgeted.drawnMode(rs.mode);  // what the budget draws (exact and the others fall back to parallax)
  PackReader whole;
  SA_RETURN_IF_ERROR(whole.open(packPath, PageLoad::kOnDemand));
  Renderer full;
  SA_RETURN_IF_ERROR(full.init(whole, whole.onDemand(), 0, Renderer::Streaming::kVisible));
  SA_RETURN_IF_ERROR(loadViewTiles(full, cams, rs));
  const double texel = whole.meta().texelSize;
  FrameResult a, b;
  for (size_t v = 0; v < cams.size(); ++v) {
    uint64_t frames = 0;
    SA_RETURN_IF_ERROR(renderSettled(budgeted, cams[v], rs, b, kReadDepth, frames));
    if (budgeted.tilesPending()) return Status::internal("bench --budget-error: view " + std::to_string(v) + " did not settle");
    SA_RETURN_IF_ERROR(full.render(cams[v], rs, a, kReadDepth));
    const RenderAgreement g = compareRenders(a.depth, b.depth, texel);
    if (print)
      std::fprintf(stderr, "bench: budget error, view %zu: IoU %.4f (%zu pixels only resident, %zu only budget), depth error median %.3f, p95 %.3f texels; settled in %llu frames, %u cells coarser to fit\n",
                   v, g.iou, g.onlyA, g.onlyB, g.depthMedian, g.depthP95, (unsigned long long)frames, b.stats.coarsened);
    out.iouMean += g.iou;
    out.iouMin = std::min(out.iouMin, g.iou);
    out.depthMedianMax = std::max(out.depthMedianMax, g.depthMedian);
    out.depthP95Max = std::max(out.depthP95Max, g.depthP95);
    out.settleFrames = std::max(out.settleFrames, frames);
    ++out.views;
  }
  out.iouMean /= double(std::max<size_t>(out.views, 1));
  return Status::ok();
}

std::string budgetErrorJson(const BudgetError& e) {
  char b[256];
  std::snprintf(b, sizeof b,
                "{\"views\": %zu, \"iou_mean\": %.6f, \"iou_min\": %.6f, \"depth_median_texels_max\": %.4f, "
                "\"depth_p95_texels_max\": %.4f, \"settle_frames_max\": %llu}",
                e.views, e.iouMean, e.iouMin, e.depthMedianMax, e.depthP95Max, (unsigned long long)e.settleFrames);
  return b;
}

// The settings every configuration starts from: the modes' options and the skip switches.
Status baseSettings(const Args& a, RenderSettings& base) {
  SA_RETURN_IF_ERROR(modeSettingsFromArgs(a, base));
  base.useColor = !a.flag("no-color");
  base.grooveAA = !a.flag("no-groove-aa");
  base.cull.frustum = !a.flag("no-frustum-cull");
  base.cull.backfaceCull = !a.flag("no-backface-cull");
  base.cull.adaptiveSteps = !a.flag("no-adaptive-steps");
  base.cull.subpixelSplats = !a.flag("no-splats");
  base.cull.frontToBack = !a.flag("no-sort");
  return Status::ok();
}

// One configuration per mode (per --iterations where the mode marches), then with
// --compare-skips each skip turned off alone, all of them, and the level-of-detail switch.
std::vector<Config> makeConfigs(const RenderSettings& base, const std::vector<RenderMode>& modes,
                                const std::vector<int>& iters, bool compareSkips) {
  std::vector<Config> configs;
  for (RenderMode m : modes) {
    if (m == RenderMode::kPoints) {
      Config c{base, "-"};
      c.settings.mode = m;
      configs.push_back(c);
      continue;
    }
    for (int it : iters) {
      Config c{base, "all"};
      c.settings.mode = m;
      c.settings.iterations = it;
      configs.push_back(c);
      // No linear steps: one configuration (gdm has them where its height-field cells take parallax).
      if (m != RenderMode::kParallax && !(m == RenderMode::kGdm && base.gdmParallaxElsewhere)) break;
    }
  }
  if (compareSkips) {
    const int it = iters.back();
    auto off = [&](const char* label, auto edit) {
      Config c{base, label};
      c.settings.iterations = it;
      edit(c.settings.cull);
      configs.push_back(c);
    };
    off("no-frustum-cull", [](CullOptions& o) { o.frustum = false; });
    off("no-backface-cull", [](CullOptions& o) { o.backfaceCull = false; });
    off("no-adaptive-steps", [](CullOptions& o) { o.adaptiveSteps = false; });
    off("no-splats", [](CullOptions& o) { o.subpixelSplats = false; });
    off("no-sort", [](CullOptions& o) { o.frontToBack = false; });
    off("none", [](CullOptions& o) {
      o.frustum = o.backfaceCull = o.adaptiveSteps = o.subpixelSplats = o.frontToBack = false;
    });
    // What the level-of-detail switch saves: parallax with boxes under --auto-pixels as slices.
    Config lod{base, "all+auto-slices"};
    lod.settings.mode = RenderMode::kAuto;
    lod.settings.iterations = it;
    configs.push_back(lod);
  }
  return configs;
}

// Every configuration's frames (on a terminal a bar with the time left): its CSV rows, its JSON
// object and its table row. One configuration after the other, or with `interleave` frame by frame
// in turn (each configuration's frame f, then each one's f + 1), so that a drift of the machine's
// speed during the run falls on every configuration alike and their ratio holds.
Status runConfigs(Renderer& renderer, const PackReader& pack, const std::vector<Camera>& cams,
                  const std::vector<Config>& configs, int64_t warmup, int64_t frames, bool interleave, bool quiet,
                  bool budgeted, std::ostringstream& csv, std::ostringstream& json, std::vector<Row>& rows) {
  Progress progress(!quiet, "bench", "frames");
  const uint64_t totalFrames = uint64_t(frames + warmup) * configs.size();
  uint64_t framesDone = 0;
  rows.assign(configs.size(), Row{});
  for (size_t ci = 0; ci < configs.size(); ++ci) rows[ci].config = configs[ci];
  // Frame f of configuration ci, warm-up frames first.
  auto frame = [&](size_t ci, int64_t f) -> Status {
    progress("frames", ++framesDone, totalFrames);
    return f < warmup ? warmFrame(renderer, cams, configs[ci], f) : timedFrame(renderer, cams, ci, f - warmup, csv, rows[ci]);
  };
  const int64_t all = warmup + frames;
  if (interleave) {
    for (int64_t f = 0; f < all; ++f)
      for (size_t ci = 0; ci < configs.size(); ++ci) SA_RETURN_IF_ERROR(frame(ci, f));
  } else {
    for (size_t ci = 0; ci < configs.size(); ++ci)
      for (int64_t f = 0; f < all; ++f) SA_RETURN_IF_ERROR(frame(ci, f));
  }
  progress.finish();
  for (size_t ci = 0; ci < configs.size(); ++ci) {
    SA_RETURN_IF_ERROR(finishRow(renderer, cams, rows[ci]));
    json << (ci ? ", " : "") << rowJson(rows[ci], renderer, pack, budgeted);
  }
  return Status::ok();
}

void printStream(const StreamReport& r, uint32_t cells) {
  std::fprintf(stderr,
               "bench: streamed: pack opened in %.1f ms, GL ready at %.1f ms, first frame at %.1f ms, every visible cell drawn at %.1f ms "
               "(%llu frames, %u of %u tiles resident)\n",
               r.openMs, r.initMs, r.firstFrameMs, r.viewCompleteMs, (unsigned long long)r.frames, r.tilesResident, cells);
}

// --budget-error: the budget's image error against an unlimited render, on stderr and in the JSON.
Status addBudgetError(Renderer& renderer, const std::string& packPath, const std::vector<Camera>& cams,
                      const RenderSettings& rs, bool quiet, std::ostringstream& json) {
  BudgetError be;
  SA_RETURN_IF_ERROR(measureBudgetError(renderer, packPath, cams, rs, !quiet, be));
  if (!quiet)
    std::fprintf(stderr, "bench: budget error over %zu views: IoU mean %.4f, min %.4f; depth error median at most %.3f texels (p95 at most %.3f)\n",
                 be.views, be.iouMean, be.iouMin, be.depthMedianMax, be.depthP95Max);
  json << ", \"budget_error\": " << budgetErrorJson(be);
  return Status::ok();
}

}  // namespace

int cmdBench(int argc, char** argv) {
  Args a;
  Status s = a.parse(argc, argv,
                     {"path", "orbit", "zoom", "size", "fov", "up", "warmup", "frames", "mode", "iterations", "slices", "auto-pixels", "gdm-elsewhere", "csv", "gpu-budget"},
                     {"compare-skips", "interleave", "stream", "budget-error", "no-color", "no-groove-aa", "no-frustum-cull", "no-backface-cull", "no-adaptive-steps", "no-splats",
                      "no-sort", "json", "quiet", "help"},
                     {{"q", "quiet"}, {"h", "help"}});
  if (a.flag("help")) {
    std::printf(kHelp, kGpuBudgetHelp);
    return 0;
  }
  if (!s) return reportError(s);
  if (a.positionals().size() != 1) return reportError(Status::badInput("bench: give exactly one pack (see --help)"));
  const auto t0 = std::chrono::steady_clock::now();
  auto budgetArg = gpuBudgetFor(a, a.positionals()[0]);
  if (!budgetArg) return reportError(budgetArg.status());
  GpuBudget budget = *budgetArg;
  PackReader pack;
  // Without a budget or --stream, the tiles the cameras draw are decoded before the first frame
  // (loadViewTiles), the others never.
  s = pack.open(a.positionals()[0], budget.bytes ? PageLoad::kTiles : PageLoad::kOnDemand);
  if (!s) return reportError(s);
  StreamReport streamed;
  streamed.openMs = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (a.has("csv")) {
    std::vector<std::string> inputs = packSources(pack);  // points mode reads them
    inputs.insert(inputs.end(), {a.positionals()[0], a.get("path")});
    s = checkNotAnInput(a.get("csv"), inputs, "--csv");
    if (!s) return reportError(s);
  }
  std::vector<Camera> cams;
  s = camerasFromArgs(a, pack, 60, 1024, cams);
  if (!s) return reportError(s);
  auto warmup = parseInt("warmup", a.get("warmup", "10"), 0, 100000);
  auto frames = parseInt("frames", a.get("frames", "200"), 1, 1000000);
  if (!warmup) return reportError(warmup.status());
  if (!frames) return reportError(frames.status());
  std::vector<RenderMode> modes;
  std::vector<int> iters;
  s = modesAndIterations(a, modes, iters);
  if (!s) return reportError(s);
  RenderSettings base;
  s = baseSettings(a, base);
  if (!s) return reportError(s);
  const std::vector<Config> configs = makeConfigs(base, modes, iters, a.flag("compare-skips"));

  EglContext ctx;
  s = ctx.init();
  if (!s) return reportError(s);
  const bool quiet = a.flag("quiet") || a.flag("json");
  boundByGpuMemory(budget, "bench", a.flag("quiet"));
  if (a.flag("budget-error") && !budget.bytes)
    return reportError(Status::badInput("bench: --budget-error compares a --gpu-budget render with the unlimited one: give --gpu-budget"));
  const bool stream = a.flag("stream") || budget.bytes > 0;
  Renderer renderer;
  s = renderer.init(pack, stream || pack.onDemand(), budget.bytes,
                    stream ? Renderer::Streaming::kWholePack : Renderer::Streaming::kVisible);
  if (!s) return reportError(s);
  for (size_t i = 0; i < configs.size() && !stream; ++i)
    if (s = loadViewTiles(renderer, cams, configs[i].settings); !s) return reportError(s);
  streamed.initMs = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (a.flag("stream")) {
    s = streamFirstView(renderer, cams[0], configs[0].settings, t0, streamed);
    if (!s) return reportError(s);
    if (!quiet) printStream(streamed, pack.meta().cellCount);
  }
  for (RenderMode m : modes) warnIfModeFallsBack(renderer, pack, m);
  if (std::find(modes.begin(), modes.end(), RenderMode::kPoints) != modes.end()) {
    if (!quiet) std::fprintf(stderr, "bench: reading the source points for the points baseline...\n");
    s = uploadSourcePoints(pack, renderer);
    if (!s) return reportError(s);
  }
  std::ostringstream csv;
  csv << "config,mode,iterations,skips,frame,camera,gpu_ms,cpu_ms,boxes_submitted,boxes_culled,boxes_drawn,"
         "boxes_inside,splats,points,fragments\n";
  std::ostringstream json;
  json << "{\"pack\": \"" << jsonEscape(pack.path()) << "\", \"renderer\": \"" << jsonEscape(ctx.renderer())
       << "\", \"width\": " << cams[0].width << ", \"height\": " << cams[0].height << ", \"frames\": " << *frames
       << ", \"warmup\": " << *warmup << ", \"cameras\": " << cams.size();
  if (budget.bytes) json << ", \"gpu_budget\": " << budget.bytes << ", \"gpu_budget_default\": " << (budget.automatic ? "true" : "false");
  if (a.flag("stream")) json << ", \"stream\": " << streamJson(streamed, pack.meta().cellCount);
  json << ", \"configs\": [";
  std::vector<Row> rows;
  s = runConfigs(renderer, pack, cams, configs, *warmup, *frames, a.flag("interleave"), quiet, budget.bytes > 0, csv, json, rows);
  if (!s) return reportError(s);
  if (!quiet) printTable(rows, ctx.renderer());
  json << "]";
  if (a.flag("budget-error")) {
    s = addBudgetError(renderer, a.positionals()[0], cams, configs[0].settings, quiet, json);
    if (!s) return reportError(s);
  }
  json << "}\n";
  if (a.has("csv")) {
    const std::string text = csv.str();
    s = writeFileAtomic(a.get("csv"), text.data(), text.size());
    if (!s) return reportError(s);
  }
  if (a.flag("json")) std::fputs(json.str().c_str(), stdout);
  if (!quiet)
    std::fprintf(stderr, "renderer: %s; %zu camera(s), %lld frames per configuration, times in ms; atlas %.1f MiB on the GPU\n",
                 ctx.renderer().c_str(), cams.size(), (long long)*frames, renderer.gpuBytes() / 1048576.0);
  return 0;
}

}  // namespace sa
