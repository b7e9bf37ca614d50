#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <sstream>

#include "atlas/pack_file.h"
#include "cli/args.h"
#include "cli/commands.h"
#include "cli/view_setup.h"
#include "common/fileio.h"
#include "preprocess/nearest.h"
#include "viewer/egl_context.h"
#include "viewer/eval.h"
#include "viewer/renderer.h"
#include "viewer/source_points.h"

namespace sa {

const char* embeddedScript(std::string_view name);

namespace {

const char* kHelp =
    "usage: scanatlas eval PACK [--reference MESH|SCANS.conf] [--far] [--path cams.json | --orbit N] [options]\n"
    "\n"
    "Image error of the pack's renders, with the same cameras, by two measures:\n"
    "\n"
    "  against a reference (--reference): the reference's triangles rasterized on the CPU in\n"
    "  double precision (a mesh in any format pack reads: PLY, OBJ, OFF, STL, DRC; or a Stanford\n"
    "  scan set whose range grids are triangulated: neighbouring grid samples, edges longer than\n"
    "  --max-edge dropped). Per view and configuration: coverage IoU, silhouette error (pixels\n"
    "  whose coverage differs / reference silhouette perimeter), depth error median and p95\n"
    "  relative to the bounding-box diagonal, normal angular error median, PSNR of the shaded\n"
    "  image (both shaded alike: Lambert, head light, no scan colour), interior holes (pixels\n"
    "  where the reference has surface on the pixel and its 8 neighbours and the render has\n"
    "  none: pinholes and seams), and the frame time. --json also counts the pixels only the\n"
    "  render covers (only_render: surplus, wider silhouettes) and only the reference covers\n"
    "  (only_reference: holes, thin parts missed), which tell what an IoU below 1 is made of.\n"
    "\n"
    "  always (parallax): seam, the mean angle between the shading normals of neighbouring pixels\n"
    "  drawn by different cells over the same for pixels of one cell (on continuous surface; 1 =\n"
    "  cell borders are invisible in the shading).\n"
    "\n"
    "  reference-free (--far, and always when no --reference is given): for every rendered\n"
    "  surface pixel, the 3-D distance from its hit point to the nearest input point (a kd-tree\n"
    "  over the pack's source files), in units of the pack's sample spacing: median, p99 and the\n"
    "  fractions of pixels beyond 3 and beyond 10 spacings. Surface drawn where no point is\n"
    "  (walls along scan edges, interpolation across height jumps) shows up here. '>3 loc':\n"
    "  beyond 3 of the nearest point's own area spacing where that is wider than the pack's (a\n"
    "  region sampled more sparsely than the rest, drawn as surface by pack --sparse-reach).\n"
    "\n"
    "options:\n"
    "  --reference FILE       the ground truth (a mesh or a .conf scan set)\n"
    "  --far                  also the reference-free measure when --reference is given\n"
    "  --max-edge X           scan sets: longest grid triangle edge kept (default 3 x median)\n"
    "  --path FILE | --orbit N   cameras (default --orbit 8); --zoom F as for bench\n"
    "  --size WxH             (default 1024x1024); --fov DEG, --up X,Y,Z as for render (up\n"
    "                         defaults to the pack's up axis)\n"
    "  --mode LIST            parallax, exact, vdm, gdm, grooves (each needs 'scanatlas bake PACK --mode M',\n"
    "                         else its fallback is drawn and said), slices, auto, points (default\n"
    "                         parallax); one row per mode (per --iterations for parallax)\n"
    "  --iterations LIST      parallax step bounds (default 64)\n"
    "  --slices N|auto        slices mode: quads per cell (default 16; auto: from each cell's distance)\n"
    "  --gdm-elsewhere M      gdm mode: how the cells that are height fields are drawn, exact (the\n"
    "                         default) or parallax (--iterations): then gdm differs from parallax\n"
    "                         only where it draws a forced cell's surface\n"
    "  --auto-pixels P        auto mode: boxes under P pixels across are drawn as slices, a pixel\n"
    "                         apart along the view (depth error <= sqrt(3) pixels); the others by\n"
    "                         the parallax march (default 8)\n"
    "  --repeat N             timed rounds over all views, after one warm-up round (median per\n"
    "                         view; default 3)\n"
    "  --csv FILE             one row per view and configuration plus 'all' summary rows\n"
    "  --plot FILE.png        run time vs error plot (also FILE.svg); needs python3-matplotlib\n"
    "  --images DIR           also write, per view and configuration, what was measured:\n"
    "                         LABEL_V.png (the shaded render), LABEL_V.pfm (its linear view depth)\n"
    "                         and with --reference LABEL_V_error.png (grey: both cover, brighter\n"
    "                         and redder up to 0.2 % of the diagonal of depth error; blue: the\n"
    "                         render alone covers; yellow: the reference alone),\n"
    "                         LABEL_V_normal_error.pfm (degrees; inf where not both), reference_V.png\n"
    "                         and reference_V.pfm. LABEL is e.g. parallax-12, gdm+parallax-12, exact\n"
    "  --json                 summary as JSON on stdout\n"
    "  -q, --quiet            no tables (per view and summary, on stderr)\n";

struct Options {
  std::vector<Camera> cams;
  std::vector<RenderMode> modes;
  std::vector<int> iterations;
  int repeat = 3;
  double maxEdge = 0;
  std::string imagesDir;  // --images: what each view measured, as files
  bool far = false, quiet = false, json = false;
};

// The reference renders, made once for every configuration.
struct Reference {
  TriangleMesh mesh;
  std::vector<ReferenceView> views;
  std::vector<Image> shaded;
  double diag = 0;
};

struct ViewResult {
  double ms = 0;
  std::optional<ViewMetrics> ref;
  std::optional<FarStats> far;
  std::optional<SeamStats> seam;  // parallax: normals across cell borders vs within cells
};

struct Row {
  std::string mode, skips;
  int iterations = 0;
  double frameMs = 0;
  bool hasRef = false;
  double iou = 0, iouMin = 1, sil = 0, depthMed = 0, depthP95 = 0, normalMed = -1, psnr = 0;
  size_t holes = 0, onlyRender = 0, onlyReference = 0;  // pixels covered by one image alone
  std::optional<FarStats> far;
  std::optional<SeamStats> seam;
  std::vector<ViewResult> views;
  WorkCounters work;  // from the (untimed) error renders
};

Status parseOptions(const Args& a, const PackReader& pack, Options& o) {
  SA_RETURN_IF_ERROR(camerasFromArgs(a, pack, 8, 1024, o.cams));
  if (a.has("max-edge")) {
    auto v = parseNumber("max-edge", a.get("max-edge"));
    if (!v) return v.status();
    o.maxEdge = *v;
  }
  auto repeat = parseInt("repeat", a.get("repeat", "3"), 1, 1000);
  if (!repeat) return repeat.status();
  o.repeat = int(*repeat);
  SA_RETURN_IF_ERROR(modesAndIterations(a, o.modes, o.iterations));
  if (a.has("plot") && std::system("/usr/bin/python3 -c 'import matplotlib' >/dev/null 2>&1") != 0)
    return Status::badInput("--plot needs Debian's python3-matplotlib: apt-get install python3-matplotlib");
  if (a.has("plot") && !a.has("reference"))
    return Status::badInput("--plot draws run time against the reference's depth error and IoU: give --reference");
  o.far = a.flag("far") || !a.has("reference");
  std::vector<std::string> inputs = packSources(pack);  // the far measure and points mode read them
  inputs.insert(inputs.end(), {a.positionals()[0], a.get("reference"), a.get("path")});
  for (const char* opt : {"csv", "plot"})
    if (a.has(opt)) SA_RETURN_IF_ERROR(checkNotAnInput(a.get(opt), inputs, std::string("--") + opt));
  if (a.has("plot"))
    SA_RETURN_IF_ERROR(checkNotAnInput(std::filesystem::path(a.get("plot")).replace_extension(".svg").string(), inputs, "--plot"));
  if (a.has("images")) {
    o.imagesDir = a.get("images");
    std::error_code ec;
    if (std::filesystem::exists(o.imagesDir, ec) && !std::filesystem::is_directory(o.imagesDir, ec))
      return Status::badInput(o.imagesDir + ": --images names a folder, and this is a file");
  }
  o.json = a.flag("json");
  o.quiet = a.flag("quiet") || o.json;
  return Status::ok();
}

Result<Reference> makeReference(const std::string& path, const Options& o, const RenderSettings& base) {
  auto mesh = loadReference(path, o.maxEdge);
  if (!mesh) return mesh.status();
  Reference r;
  r.mesh = std::move(*mesh);
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (size_t i = 0; i < r.mesh.positions.size(); i += 3) {
    lo = lo.cwiseMin(Eigen::Vector3d(&r.mesh.positions[i]));
    hi = hi.cwiseMax(Eigen::Vector3d(&r.mesh.positions[i]));
  }
  r.diag = (hi - lo).norm();
  for (const Camera& c : o.cams) {
    r.views.push_back(referenceView(r.mesh, c));
    r.shaded.push_back(shadeReference(r.views.back(), c, base.baseColor, base.background));
  }
  return r;
}

// Median frame time per view, timed the way bench times: the views cycled back to back
// without read-back (llvmpipe's point rendering runs up to 3x faster right after a full
// read-back, which a frame shown on screen never gets).
Status timeViews(Renderer& renderer, const Options& o, const RenderSettings& rs, std::vector<double>& ms) {
  std::vector<std::vector<double>> perView(o.cams.size());
  for (int r = 0; r < o.repeat + 1; ++r)
    for (size_t v = 0; v < o.cams.size(); ++v) {
      FrameResult tr;
      SA_RETURN_IF_ERROR(renderer.render(o.cams[v], rs, tr, 0u));
      if (r > 0) perView[v].push_back(tr.stats.cpuMs);  // the first round warms up
    }
  ms.clear();
  for (auto& t : perView) ms.push_back(percentile(t, 0.5));
  return Status::ok();
}

std::string fileLabel(const Row& r) {
  return r.mode + (r.iterations ? "-" + std::to_string(r.iterations) : "");
}

// Where a render's coverage and depth differ from the reference's: grey where both cover
// (brighter and redder with the depth error, saturated at 0.2 % of the diagonal), blue where
// the render alone covers, yellow where the reference alone does, black where neither.
Image errorMap(const std::vector<float>& depth, const std::vector<float>& ref, int w, int h, double diag) {
  Image img{w, h, std::vector<uint8_t>(size_t(w) * h * 4, 0)};
  for (size_t i = 0; i < depth.size(); ++i) {
    uint8_t* p = &img.rgba[i * 4];
    const bool t = std::isfinite(depth[i]), r = std::isfinite(ref[i]);
    p[3] = 255;
    if (t && r) {
      const double e = std::min(1.0, std::abs(double(depth[i]) - ref[i]) / (0.002 * diag));
      p[0] = uint8_t(70 + 185 * e);
      p[1] = p[2] = uint8_t(70 + 60 * e * (1 - e));
    } else if (t) {
      p[0] = 0, p[1] = 128, p[2] = 255;
    } else if (r) {
      p[0] = 255, p[1] = 255, p[2] = 0;
    }
  }
  return img;
}

// The angle (degrees) between the render's and the reference's normals where both cover and the
// render has a normal (as evaluateView measures it: lines, not signs), else +inf.
std::vector<float> normalErrorMap(const std::vector<float>& tn, const ReferenceView& ref, size_t pixels) {
  std::vector<float> out(pixels, INFINITY);
  for (size_t i = 0; i < pixels && !tn.empty(); ++i) {
    const Eigen::Vector3d t(tn[3 * i], tn[3 * i + 1], tn[3 * i + 2]);
    const Eigen::Vector3f r(&ref.normals[3 * i]);
    if (t.norm() > 0.5 && std::isfinite(ref.depth[i]))
      out[i] = float(std::acos(std::min(1.0, std::abs(t.dot(r.cast<double>())) / t.norm())) * 180 / M_PI);
  }
  return out;
}

Status saveViewImages(const Options& o, const std::string& label, size_t v, const FrameResult& fr,
                      const Reference* ref) {
  const std::string stem = (std::filesystem::path(o.imagesDir) / (label + "_" + std::to_string(v))).string();
  SA_RETURN_IF_ERROR(writePng(stem + ".png", fr.color));
  SA_RETURN_IF_ERROR(writePfm(stem + ".pfm", fr.color.width, fr.color.height, fr.depth));
  if (!ref) return Status::ok();
  SA_RETURN_IF_ERROR(writePfm(stem + "_normal_error.pfm", fr.color.width, fr.color.height,
                              normalErrorMap(fr.normals, ref->views[v], fr.depth.size())));
  return writePng(stem + "_error.png",
                  errorMap(fr.depth, ref->views[v].depth, fr.color.width, fr.color.height, ref->diag));
}

// Makes the --images folder and writes the reference's views into it.
Status startImages(const Options& o, const Reference* ref) {
  std::error_code ec;
  std::filesystem::create_directories(o.imagesDir, ec);
  if (ec) return Status::badInput(o.imagesDir + ": cannot create the --images folder: " + ec.message());
  if (!ref) return Status::ok();
  for (size_t v = 0; v < o.cams.size(); ++v) {
    const std::string stem = (std::filesystem::path(o.imagesDir) / ("reference_" + std::to_string(v))).string();
    SA_RETURN_IF_ERROR(writePng(stem + ".png", ref->shaded[v]));
    SA_RETURN_IF_ERROR(writePfm(stem + ".pfm", o.cams[v].width, o.cams[v].height, ref->views[v].depth));
  }
  return Status::ok();
}

Status evaluateConfig(Renderer& renderer, const PackReader& pack, const Options& o, const Reference* ref,
                      const NearestSamples* samples, const std::vector<float>& localScale, const RenderSettings& rs,
                      Row& row) {
  std::vector<double> ms;
  SA_RETURN_IF_ERROR(timeViews(renderer, o, rs, ms));
  const Eigen::Vector3d origin(pack.meta().origin);
  std::vector<double> depthAll, normalAll, farAll, localAll;
  double psnrSum = 0, iouSum = 0, silSum = 0;
  std::optional<SeamStats> seamAll;
  for (size_t v = 0; v < o.cams.size(); ++v) {
    FrameResult fr;
    const bool parallax = rs.mode != RenderMode::kPoints;  // a height-field mode: per-cell seams too
    const unsigned want = kReadColor | kReadDepth | (parallax ? kReadNormals | kReadCells : 0u);
    RenderSettings counted = rs;
    counted.countWork = parallax;
    SA_RETURN_IF_ERROR(renderer.render(o.cams[v], counted, fr, want));
    if (parallax) row.work.add(fr.stats.work);
    if (!o.imagesDir.empty()) SA_RETURN_IF_ERROR(saveViewImages(o, fileLabel(row), v, fr, ref));
    ViewResult vr;
    vr.ms = ms[v];
    if (parallax) {
      vr.seam = seamStats(o.cams[v], fr.depth, fr.normals, fr.cells);
      if (!seamAll) seamAll = SeamStats{};
      seamAll->borderMeanDeg += vr.seam->borderMeanDeg * double(vr.seam->borderPairs);
      seamAll->insideMeanDeg += vr.seam->insideMeanDeg * double(vr.seam->insidePairs);
      seamAll->borderPairs += vr.seam->borderPairs;
      seamAll->insidePairs += vr.seam->insidePairs;
    }
    if (ref) {
      vr.ref = evaluateView(fr.color, fr.depth, fr.normals, ref->views[v], ref->shaded[v], ref->diag);
      depthAll.insert(depthAll.end(), vr.ref->depthErrors.begin(), vr.ref->depthErrors.end());
      normalAll.insert(normalAll.end(), vr.ref->normalErrors.begin(), vr.ref->normalErrors.end());
      psnrSum += vr.ref->psnr;
      iouSum += vr.ref->iou;
      silSum += vr.ref->silhouetteError;
      row.iouMin = std::min(row.iouMin, vr.ref->iou);
      row.holes += vr.ref->interiorHoles;
      row.onlyRender += vr.ref->onlyTest;
      row.onlyReference += vr.ref->onlyRef;
      vr.ref->depthErrors.clear();
      vr.ref->normalErrors.clear();
    }
    if (samples) {
      const std::vector<double> hits = surfacePoints(o.cams[v], fr.depth, origin);
      std::vector<double> d(hits.size() / 3), local(d.size(), 1.0);
      std::vector<uint32_t> nearest(d.size());
      samples->distances(hits.data(), d.size(), d.data(), nearest.data());
      for (double& x : d) x /= pack.meta().sampleSpacing;
      for (size_t i = 0; i < d.size(); ++i)
        if (nearest[i] < localScale.size()) local[i] = localScale[nearest[i]];
      vr.far = summarizeFar(d, &local);
      farAll.insert(farAll.end(), d.begin(), d.end());
      localAll.insert(localAll.end(), local.begin(), local.end());
    }
    row.views.push_back(std::move(vr));
  }
  const double n = double(o.cams.size());
  row.frameMs = percentile(ms, 0.5);
  if (ref) {
    row.hasRef = true;
    row.iou = iouSum / n;
    row.sil = silSum / n;
    row.psnr = psnrSum / n;
    row.depthMed = percentile(depthAll, 0.5);
    row.depthP95 = percentile(depthAll, 0.95);
    row.normalMed = normalAll.empty() ? -1 : percentile(normalAll, 0.5);
  }
  if (samples) row.far = summarizeFar(farAll, &localAll);
  if (seamAll) {
    seamAll->borderMeanDeg /= double(std::max<size_t>(1, seamAll->borderPairs));
    seamAll->insideMeanDeg /= double(std::max<size_t>(1, seamAll->insidePairs));
    row.seam = seamAll;
  }
  return Status::ok();
}

std::string fmtNormal(double deg) { return deg < 0 ? "-" : std::to_string(deg).substr(0, 6); }

// One line of figures (a view or a configuration's summary) for the terminal tables.
void printFigures(const char* label, double ms, const Row* sum, const ViewResult* view) {
  std::fprintf(stderr, "%-26s %9.2f", label, ms);
  if (sum && sum->hasRef)
    std::fprintf(stderr, " %8.4f %8.4f %7.3f %11.5f %11.4f %9s %7.2f %7zu", sum->iou, sum->iouMin, sum->sil,
                 100 * sum->depthMed, 100 * sum->depthP95, fmtNormal(sum->normalMed).c_str(), sum->psnr, sum->holes);
  if (view && view->ref)
    std::fprintf(stderr, " %8.4f %8s %7.3f %11.5f %11.4f %9s %7.2f %7zu", view->ref->iou, "", view->ref->silhouetteError,
                 100 * view->ref->depthMedian, 100 * view->ref->depthP95, fmtNormal(view->ref->normalMedianDeg).c_str(),
                 view->ref->psnr, view->ref->interiorHoles);
  const std::optional<SeamStats>& seam = sum ? sum->seam : view->seam;
  if (seam) std::fprintf(stderr, " %6.2f", seam->ratio());
  else std::fprintf(stderr, " %6s", "-");
  const std::optional<FarStats>& far = sum ? sum->far : view->far;
  if (far)
    std::fprintf(stderr, " %8.3f %8.3f %9.4f %9.4f %9.4f", far->median, far->p99, 100 * far->beyond3, 100 * far->beyond10,
                 100 * far->beyond3Local);
  std::fprintf(stderr, "\n");
}

void printHeader(const char* first, bool ref, bool far) {
  std::fprintf(stderr, "%-26s %9s", first, "frame ms");
  if (ref)
    std::fprintf(stderr, " %8s %8s %7s %11s %11s %9s %7s %7s", "IoU", "IoU min", "silh.", "depth med%", "depth p95%",
                 "normal°", "PSNR dB", "holes");
  std::fprintf(stderr, " %6s", "seam");
  if (far) std::fprintf(stderr, " %8s %8s %9s %9s %9s", "far med", "far p99", ">3 sp %", ">10 sp %", ">3 loc %");
  std::fprintf(stderr, "\n");
}

std::string configLabel(const Row& r) {
  return r.mode + (r.iterations ? " " + std::to_string(r.iterations) + " it" : "");
}

void printTables(const std::vector<Row>& rows) {
  const bool ref = !rows.empty() && rows[0].hasRef, far = !rows.empty() && rows[0].far.has_value();
  printHeader("view", ref, far);
  for (const Row& r : rows)
    for (size_t v = 0; v < r.views.size(); ++v) {
      const std::string label = configLabel(r) + ", view " + std::to_string(v);
      printFigures(label.c_str(), r.views[v].ms, nullptr, &r.views[v]);
    }
  std::fprintf(stderr, "\n");
  printHeader("configuration (all views)", ref, far);
  for (const Row& r : rows) printFigures(configLabel(r).c_str(), r.frameMs, &r, nullptr);
  std::fprintf(stderr, "seam: mean angle between shading normals of neighbouring pixels from different cells over the same "
                       "within a cell (1 = no seams)\n");
  if (far)
    std::fprintf(stderr, "far: distance from each rendered surface pixel to the nearest input point, in sample spacings "
                         "(loc: in that point's own spacing where it is wider)\n");
}

std::string seamJson(const std::optional<SeamStats>& s) {
  if (!s) return "null";
  char buf[256];
  std::snprintf(buf, sizeof(buf), "{\"ratio\": %.6g, \"border_mean_deg\": %.6g, \"inside_mean_deg\": %.6g, \"border_pairs\": %zu, "
                "\"inside_pairs\": %zu}", s->ratio(), s->borderMeanDeg, s->insideMeanDeg, s->borderPairs, s->insidePairs);
  return buf;
}

std::string farJson(const std::optional<FarStats>& f) {
  if (!f) return "null";
  char buf[256];
  std::snprintf(buf, sizeof(buf),
                "{\"pixels\": %zu, \"median\": %.6g, \"p99\": %.6g, \"beyond3\": %.6g, \"beyond10\": %.6g, "
                "\"beyond3_local\": %.6g}",
                f->pixels, f->median, f->p99, f->beyond3, f->beyond10, f->beyond3Local);
  return buf;
}

void printJson(const std::vector<Row>& rows, const PackReader& pack, const Reference* ref, const Options& o,
               const std::string& renderer) {
  std::printf("{\"pack\": \"%s\", \"reference\": %s, \"renderer\": \"%s\", \"views\": %zu, \"width\": %d, "
              "\"height\": %d, \"diagonal\": %s, \"spacing\": %.9g, \"configs\": [",
              jsonEscape(pack.path()).c_str(), ref ? ("\"" + jsonEscape(ref->mesh.description) + "\"").c_str() : "null",
              jsonEscape(renderer).c_str(), o.cams.size(), o.cams[0].width, o.cams[0].height,
              ref ? std::to_string(ref->diag).c_str() : "null", pack.meta().sampleSpacing);
  for (size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    std::printf("%s{\"mode\": \"%s\", \"iterations\": %d, \"frame_ms\": %.4f", i ? ", " : "", r.mode.c_str(), r.iterations,
                r.frameMs);
    if (r.hasRef)
      std::printf(", \"iou\": %.6f, \"iou_min\": %.6f, \"silhouette_error\": %.6f, \"depth_median\": %.8g, "
                  "\"depth_p95\": %.8g, \"normal_median_deg\": %s, \"psnr\": %.4f, \"interior_holes\": %zu, "
                  "\"only_render\": %zu, \"only_reference\": %zu",
                  r.iou, r.iouMin, r.sil, r.depthMed, r.depthP95,
                  r.normalMed < 0 ? "null" : std::to_string(r.normalMed).c_str(), r.psnr, r.holes, r.onlyRender,
                  r.onlyReference);
    if (r.work.valid)
      std::printf(", \"work\": {\"unit\": \"%s\", \"rays\": %llu, \"mean\": %.3f, \"p50\": %u, \"p90\": %u, \"p99\": %u, "
                  "\"max\": %u, \"capped\": %llu}", r.mode == "parallax" ? "samples" : "nodes", (unsigned long long)r.work.rays,
                  r.work.mean(), r.work.p50, r.work.p90, r.work.p99, r.work.max, (unsigned long long)r.work.capped);
    std::printf(", \"far\": %s, \"seam\": %s, \"per_view\": [", farJson(r.far).c_str(), seamJson(r.seam).c_str());
    for (size_t v = 0; v < r.views.size(); ++v) {
      const ViewResult& vr = r.views[v];
      std::printf("%s{\"view\": %zu, \"frame_ms\": %.4f", v ? ", " : "", v, vr.ms);
      if (vr.ref)
        std::printf(", \"iou\": %.6f, \"depth_median\": %.8g, \"depth_p95\": %.8g, \"normal_median_deg\": %s, "
                    "\"interior_holes\": %zu, \"only_render\": %zu, \"only_reference\": %zu",
                    vr.ref->iou, vr.ref->depthMedian, vr.ref->depthP95,
                    vr.ref->normalMedianDeg < 0 ? "null" : std::to_string(vr.ref->normalMedianDeg).c_str(),
                    vr.ref->interiorHoles, vr.ref->onlyTest, vr.ref->onlyRef);
      std::printf(", \"far\": %s, \"seam\": %s}", farJson(vr.far).c_str(), seamJson(vr.seam).c_str());
    }
    std::printf("]}");
  }
  std::printf("]}\n");
}

std::string csvText(const std::vector<Row>& rows, const PackReader& pack) {
  std::ostringstream csv;
  csv << "pack,mode,iterations,skips,view,frame_ms,iou,silhouette_error,depth_median,depth_p95,normal_median_deg,psnr,"
         "interior_holes,far_median,far_p99,far_beyond3,far_beyond10,far_beyond3_local\n";
  auto farCols = [&](const std::optional<FarStats>& f) {
    if (!f) return std::string(",,,,");
    std::ostringstream s;
    s << f->median << "," << f->p99 << "," << f->beyond3 << "," << f->beyond10 << "," << f->beyond3Local;
    return s.str();
  };
  for (const Row& r : rows) {
    const std::string head = jsonEscape(pack.path()) + "," + r.mode + "," + std::to_string(r.iterations) + "," + r.skips + ",";
    for (size_t v = 0; v < r.views.size(); ++v) {
      const ViewResult& vr = r.views[v];
      csv << head << v << "," << vr.ms << ",";
      if (vr.ref)
        csv << vr.ref->iou << "," << vr.ref->silhouetteError << "," << vr.ref->depthMedian << "," << vr.ref->depthP95
            << "," << vr.ref->normalMedianDeg << "," << vr.ref->psnr << "," << vr.ref->interiorHoles << ",";
      else
        csv << ",,,,,,,";
      csv << farCols(vr.far) << "\n";
    }
    csv << head << "all," << r.frameMs << ",";
    if (r.hasRef)
      csv << r.iou << "," << r.sil << "," << r.depthMed << "," << r.depthP95 << "," << r.normalMed << "," << r.psnr << ","
          << r.holes << ",";
    else
      csv << ",,,,,,,";
    csv << farCols(r.far) << "\n";
  }
  return csv.str();
}

Status writePlot(const std::string& text, const std::string& out) {
  ScratchDir tmp;
  SA_RETURN_IF_ERROR(tmp.create(std::filesystem::temp_directory_path().string(), "scanatlas-plot-"));
  const std::string csvPath = joinPath(tmp.path(), "summary.csv"), script = joinPath(tmp.path(), "plot.py");
  SA_RETURN_IF_ERROR(writeFileAtomic(csvPath, text.data(), text.size()));
  const char* py = embeddedScript("plot_tradeoff.py");
  SA_RETURN_IF_ERROR(writeFileAtomic(script, py, std::strlen(py)));
  const std::string cmd = "/usr/bin/python3 '" + script + "' '" + csvPath + "' '" + out + "'";
  if (std::system(cmd.c_str()) != 0) return Status::internal("plotting failed: " + cmd);
  return Status::ok();
}

int runEval(const Args& a) {
  PackReader pack;
  Status s = pack.open(a.positionals()[0], PageLoad::kOnDemand);  // the tiles the views draw: loadViewTiles
  if (!s) return reportError(s);
  Options o;
  s = parseOptions(a, pack, o);
  if (!s) return reportError(s);
  RenderSettings base;
  s = modeSettingsFromArgs(a, base);
  if (!s) return reportError(s);
  base.useColor = false;  // both images shaded alike
  std::unique_ptr<Reference> ref;
  if (a.has("reference")) {
    auto r = makeReference(a.get("reference"), o, base);
    if (!r) return reportError(r.status());
    ref = std::make_unique<Reference>(std::move(*r));
    if (!o.quiet) std::fprintf(stderr, "eval: reference %s\n", ref->mesh.description.c_str());
  }
  if (!o.imagesDir.empty()) {
    s = startImages(o, ref.get());
    if (!s) return reportError(s);
  }
  std::unique_ptr<NearestSamples> samples;
  SourcePoints src;
  const bool needPoints = o.far || std::count(o.modes.begin(), o.modes.end(), RenderMode::kPoints) > 0;
  if (needPoints) {
    s = loadSourcePoints(pack, src);
    if (!s) return reportError(s);
  }
  EglContext ctx;
  s = ctx.init();
  if (!s) return reportError(s);
  Renderer renderer;
  s = renderer.init(pack, pack.onDemand(), 0, Renderer::Streaming::kVisible);
  if (!s) return reportError(s);
  RenderSettings surface = base;  // every surface mode draws the cells the views see
  surface.mode = RenderMode::kParallax;
  if (std::count(o.modes.begin(), o.modes.end(), RenderMode::kPoints) < long(o.modes.size()))
    if (s = loadViewTiles(renderer, o.cams, surface); !s) return reportError(s);
  if (std::count(o.modes.begin(), o.modes.end(), RenderMode::kPoints) > 0) {
    s = renderer.setPoints(src.xyz, src.rgba, pack.meta().sampleSpacing);
    if (!s) return reportError(s);
  }
  std::vector<float> localScale;  // per source point: its area spacing over the pack's, at least 1
  if (o.far) {
    samples = std::make_unique<NearestSamples>(std::move(src.xyz));
    localScale = samples->areaSpacings();
    for (float& x : localScale) x = std::max(1.f, float(x / pack.meta().sampleSpacing));
  }
  std::vector<Row> rows;
  if (!o.quiet)
    for (RenderMode mode : o.modes) warnIfModeFallsBack(renderer, pack, mode);
  for (RenderMode mode : o.modes) {
    // Only parallax has linear steps (and gdm drawing its height-field cells by it); the others
    // are one configuration each.
    const bool gdmParallax = renderer.drawnMode(mode) == RenderMode::kGdm && base.gdmParallaxElsewhere;
    const bool stepped = (renderer.drawnMode(mode) == RenderMode::kParallax && mode != RenderMode::kPoints) || gdmParallax;
    const std::vector<int> its = stepped ? o.iterations : std::vector<int>{0};
    for (int it : its) {
      RenderSettings rs = base;
      rs.mode = mode;
      if (it > 0) rs.iterations = it;
      Row row;
      row.mode = modeName(mode == RenderMode::kPoints ? mode : renderer.drawnMode(mode));
      if (gdmParallax) row.mode += "+parallax";
      row.iterations = it;
      row.skips = mode == RenderMode::kPoints ? "-" : "all";
      s = evaluateConfig(renderer, pack, o, ref.get(), samples.get(), localScale, rs, row);
      if (!s) return reportError(s);
      rows.push_back(std::move(row));
    }
  }
  if (!o.quiet) {
    printTables(rows);
    std::fprintf(stderr, "renderer: %s; %zu view(s) at %dx%d", ctx.renderer().c_str(), o.cams.size(), o.cams[0].width,
                 o.cams[0].height);
    if (ref) std::fprintf(stderr, "; depth errors relative to the reference diagonal %.6g", ref->diag);
    if (samples) std::fprintf(stderr, "; sample spacing %.6g", pack.meta().sampleSpacing);
    std::fprintf(stderr, "\n");
  }
  if (o.json) printJson(rows, pack, ref.get(), o, ctx.renderer());
  const std::string text = csvText(rows, pack);
  if (a.has("csv")) {
    s = writeFileAtomic(a.get("csv"), text.data(), text.size());
    if (!s) return reportError(s);
  }
  if (a.has("plot")) {
    s = writePlot(text, a.get("plot"));
    if (!s) return reportError(s);
    if (!o.quiet) std::fprintf(stderr, "eval: wrote %s and its .svg\n", a.get("plot").c_str());
  }
  return 0;
}

}  // namespace

int cmdEval(int argc, char** argv) {
  Args a;
  Status s = a.parse(argc, argv,
                     {"reference", "max-edge", "path", "orbit", "zoom", "size", "fov", "up", "mode", "iterations", "slices", "auto-pixels", "gdm-elsewhere", "repeat", "images",
                      "csv", "plot"},
                     {"far", "json", "quiet", "help"}, {{"q", "quiet"}, {"h", "help"}});
  if (a.flag("help")) {
    std::fputs(kHelp, stdout);
    return 0;
  }
  if (!s) return reportError(s);
  if (a.positionals().size() != 1) return reportError(Status::badInput("eval: give exactly one pack (see --help)"));
  return runEval(a);
}

}  // namespace sa
