#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "atlas/pack_file.h"
#include "cli/args.h"
#include "cli/commands.h"
#include "cli/view_setup.h"
#include "common/fileio.h"
#include "viewer/egl_context.h"
#include "viewer/image_io.h"
#include "viewer/renderer.h"

namespace sa {
namespace {

const char* kHelp =
    "usage: scanatlas render PACK -o OUT.png [camera] [options]\n"
    "\n"
    "Renders a pack headless (EGL: a GPU when there is one, else Mesa llvmpipe) by ray-casting\n"
    "every height field per pixel (Lu, Low & Zheng). Coordinates are the input's world\n"
    "coordinates (after scan-set alignment). Without --gpu-budget, the tiles the views draw are\n"
    "decoded before the first image is written, and only they: a close-up of a large pack decodes\n"
    "a small part of it (the summary says how many).\n"
    "\n"
    "camera (one of):\n"
    "  --orbit N              N views around the bounding box: OUT_0.png .. OUT_{N-1}.png\n"
    "  --path FILE            the cameras of a camera-path JSON file (one image each, as --orbit)\n"
    "  --zoom F               orbit cameras F times closer to the centre\n"
    "  --eye X,Y,Z --target X,Y,Z [--up X,Y,Z]   one view (default: looking at the centre)\n"
    "  --fov DEG              vertical field of view (default 40)\n"
    "  --up X,Y,Z             up direction, also the orbit axis (default: the pack's up axis,\n"
    "                         see scanatlas info)\n"
    "  --size WxH             image size (default 1024x1024)\n"
    "\n"
    "options:\n"
    "  -o, --output FILE      the image to write: .png, or .jpg (JPEG, quality 92)\n"
    "  --depth-out FILE.pfm   also write float32 linear view depth (distance along the camera's\n"
    "                         forward axis, world units; inf where nothing was hit)\n"
    "  --mode MODE            parallax (default: linear search + bisection), exact (min/max-mipmap\n"
    "                         traversal with the exact root; needs 'scanatlas bake PACK --mode exact'),\n"
    "                         vdm (view-dependent displacement lookups; needs 'scanatlas bake PACK\n"
    "                         --mode vdm'), gdm, slices (volumetric slices: --slices quads per cell,\n"
    "                         needs nothing baked), auto (parallax near, slices far: --auto-pixels),\n"
    "                         grooves (cracks carved from their profiles; needs 'scanatlas bake PACK\n"
    "                         --mode grooves' or 'pack --modes grooves');\n"
    "                         a mode the pack lacks draws its fallback and says so\n"
    "  --slices N|auto        slices mode: quads per cell across the axis nearest the view (default 16);\n"
    "                         auto: per cell the fewest (a power of two, at most 64) that lie no farther\n"
    "                         apart along the view than a pixel at the cell's distance or a texel\n"
    "  --gdm-elsewhere M      gdm mode: how the cells that are height fields are drawn, exact (the\n"
    "                         default) or parallax (--iterations): then gdm differs from parallax\n"
    "                         only where it draws a forced cell's surface\n"
    "  --auto-pixels P        auto mode: boxes under P pixels across are drawn as slices, a pixel\n"
    "                         apart along the view (depth error <= sqrt(3) pixels); the others by\n"
    "                         the parallax march (default 8)\n"
    "  --iterations N         linear ray-march steps per height field (default 64)\n"
    "  --refine N             bisection steps after the linear search (default 6)\n"
    "  --no-groove-aa         grooves mode: one ray a pixel also where a groove is under 2 pixels wide\n"
    "  --no-color             ignore scan colours\n"
    "  --shading MODE         lambert (head light, default), normals, height (colour ramp along --up),\n"
    "                         color (scan colour, the default when the pack has colour)\n"
    "  --light X,Y,Z          a fixed light from this direction (world, toward the light) instead of\n"
    "                         the head light\n"
    "  --shadows              self-shadowing: each hit casts a second ray toward the light within its\n"
    "                         cell, by the mode's own cast (vdm: a lookup; 001 §3.2); default light\n"
    "                         45 degrees up from the first view's right\n"
    "  --edl                  eye-dome lighting (depth-based relief and outlines)\n"
    "  --boxes                draw the cells' boxes, coloured by their height axis (decomposition view)\n"
    "  --clip-box X0,Y0,Z0,X1,Y1,Z1   show only what lies inside this box (world coordinates)\n"
    "  --section PX,PY,PZ,NX,NY,NZ    show only the side of this plane the normal points to\n"
    "  --no-frustum-cull, --no-backface-cull, --no-adaptive-steps, --no-splats, --no-sort\n"
    "                         turn off what a frame skips by default (see scanatlas bench)\n"
    "  --background R,G,B     background colour, 0..1 (default 0.1,0.1,0.12)\n"
    "%s"
    "  --json                 print per-view frame times, and the tiles decoded, as JSON on stdout\n"
    "  -q, --quiet            print nothing but errors\n";

std::string indexed(const std::string& path, int i) {
  std::filesystem::path p(path);
  return (p.parent_path() / (p.stem().string() + "_" + std::to_string(i) + p.extension().string())).string();
}

// Shading, clipping, march and skip options.
Status settingsFromArgs(const Args& a, RenderSettings& rs) {
  if (a.has("mode")) {
    auto m = parseMode(a.get("mode"));
    if (!m) return Status::badInput("--mode: " + m.status().message());
    if (*m == RenderMode::kPoints) return Status::badInput("--mode points: render draws height fields; the points baseline is in bench and eval");
    rs.mode = *m;
  }
  if (a.has("iterations")) {
    auto v = parseInt("iterations", a.get("iterations"), 1, 1024);
    if (!v) return v.status();
    rs.iterations = static_cast<int>(*v);
  }
  SA_RETURN_IF_ERROR(modeSettingsFromArgs(a, rs));
  if (a.has("refine")) {
    auto v = parseInt("refine", a.get("refine"), 0, 64);
    if (!v) return v.status();
    rs.refineSteps = static_cast<int>(*v);
  }
  if (a.has("background")) {
    auto v = parseVec3("background", a.get("background"));
    if (!v) return v.status();
    for (int i = 0; i < 3; ++i) rs.background[i] = float(std::clamp((*v)[i], 0.0, 1.0));
  }
  rs.useColor = !a.flag("no-color");
  rs.grooveAA = !a.flag("no-groove-aa");
  if (a.has("shading")) {
    const std::string sh = a.get("shading");
    if (sh == "lambert") rs.shading = Shading::kLambert;
    else if (sh == "normals") rs.shading = Shading::kNormals;
    else if (sh == "height") rs.shading = Shading::kHeight;
    else if (sh == "color" || sh == "colour") rs.useColor = true;
    else return Status::badInput("--shading: expected lambert, normals, height or color, got '" + sh + "'");
  }
  rs.edl = a.flag("edl");
  if (a.has("light")) {
    auto v = parseVec3("light", a.get("light"));
    if (!v) return v.status();
    if (!(v->norm() > 0)) return Status::badInput("--light must not be zero");
    rs.headLight = false;
    rs.lightDir = v->normalized();
  }
  rs.shadows = a.flag("shadows");
  rs.showBoxes = a.flag("boxes");
  std::vector<double> n;
  if (a.has("clip-box")) {
    SA_RETURN_IF_ERROR(numberList(a, "clip-box", 6, n));
    rs.clip.box = true;
    rs.clip.lo = Eigen::Vector3d(std::min(n[0], n[3]), std::min(n[1], n[4]), std::min(n[2], n[5]));
    rs.clip.hi = Eigen::Vector3d(std::max(n[0], n[3]), std::max(n[1], n[4]), std::max(n[2], n[5]));
  }
  if (a.has("section")) {
    SA_RETURN_IF_ERROR(numberList(a, "section", 6, n));
    rs.clip.plane = true;
    rs.clip.point = Eigen::Vector3d(n[0], n[1], n[2]);
    rs.clip.normal = Eigen::Vector3d(n[3], n[4], n[5]);
    if (rs.clip.normal.norm() == 0) return Status::badInput("--section: the normal must not be zero");
  }
  rs.cull.frustum = !a.flag("no-frustum-cull");
  rs.cull.backfaceCull = !a.flag("no-backface-cull");
  rs.cull.adaptiveSteps = !a.flag("no-adaptive-steps");
  rs.cull.subpixelSplats = !a.flag("no-splats");
  rs.cull.frontToBack = !a.flag("no-sort");
  return Status::ok();
}

struct Outputs {
  std::vector<std::string> images, depths;  // one per camera (depths empty without --depth-out)
};

// The file names each view writes (OUT_i.png for several views), checked before any work: a
// known image type, a .pfm depth, never one of the command's inputs; their folders created.
Status outputsFromArgs(const Args& a, size_t views, Outputs& out) {
  SA_RETURN_IF_ERROR(checkImageExtension(a.get("output")));
  if (a.has("depth-out") && lowerExtension(a.get("depth-out")) != ".pfm")
    return Status::badInput(a.get("depth-out") + ": --depth-out writes PFM; name it .pfm");
  std::vector<std::string> inputs = {a.positionals()[0]};
  if (a.has("path")) inputs.push_back(a.get("path"));
  for (size_t i = 0; i < views; ++i) {
    out.images.push_back(views > 1 ? indexed(a.get("output"), int(i)) : a.get("output"));
    SA_RETURN_IF_ERROR(checkNotAnInput(out.images.back(), inputs, "-o"));
    if (!a.has("depth-out")) continue;
    out.depths.push_back(views > 1 ? indexed(a.get("depth-out"), int(i)) : a.get("depth-out"));
    SA_RETURN_IF_ERROR(checkNotAnInput(out.depths.back(), inputs, "--depth-out"));
  }
  // Output folders are created as needed (render -o views/bunny.png).
  for (const char* opt : {"output", "depth-out"}) {
    if (!a.has(opt)) continue;
    const std::filesystem::path dir = std::filesystem::path(a.get(opt)).parent_path();
    std::error_code ec;
    if (!dir.empty()) std::filesystem::create_directories(dir, ec);
    if (ec) return Status::badInput(dir.string() + ": cannot create the output folder: " + ec.message());
  }
  return Status::ok();
}

}  // namespace

int cmdRender(int argc, char** argv) {
  Args a;
  Status s = a.parse(argc, argv,
                     {"output", "orbit", "zoom", "path", "eye", "target", "up", "fov", "size", "depth-out", "iterations", "slices", "auto-pixels", "gdm-elsewhere", "refine",
                      "background", "shading", "clip-box", "section", "mode", "light", "gpu-budget"},
                     {"edl", "shadows", "boxes", "no-color", "no-groove-aa", "no-frustum-cull", "no-backface-cull", "no-adaptive-steps", "no-splats", "no-sort",
                      "json", "quiet", "help"}, {{"o", "output"}, {"q", "quiet"}, {"h", "help"}});
  if (a.flag("help")) {
    std::printf(kHelp, kGpuBudgetHelp);
    return 0;
  }
  if (!s) return reportError(s);
  if (a.positionals().size() != 1) return reportError(Status::badInput("render: give exactly one pack (see --help)"));
  if (!a.has("output")) return reportError(Status::badInput("render: -o OUT.png is required"));
  auto budgetArg = gpuBudgetFor(a, a.positionals()[0]);
  if (!budgetArg) return reportError(budgetArg.status());
  GpuBudget budget = *budgetArg;
  PackReader pack;
  // Without a budget, compressed pages are decoded per tile as the views ask for them: a close-up
  // of a large pack decodes what it shows, and the image is the one of a whole upload.
  s = pack.open(a.positionals()[0], budget.bytes ? PageLoad::kTiles : PageLoad::kOnDemand);
  if (!s) return reportError(s);
  std::vector<Camera> cams;
  s = camerasFromArgs(a, pack, 0, 1024, cams);
  if (!s) return reportError(s);
  RenderSettings rs;
  s = settingsFromArgs(a, rs);
  if (!s) return reportError(s);
  rs.up = cams[0].up;
  if (rs.shadows && rs.headLight) {  // a head light casts no visible shadow: light from up and to the right
    rs.headLight = false;
    rs.lightDir = (cams[0].up.normalized() + cams[0].forward().cross(cams[0].up).normalized()).normalized();
  }
  Outputs outputs;
  s = outputsFromArgs(a, cams.size(), outputs);
  if (!s) return reportError(s);
  EglContext ctx;
  s = ctx.init();
  if (!s) return reportError(s);
  const bool quiet = a.flag("quiet"), json = a.flag("json");
  boundByGpuMemory(budget, "render", quiet);
  Renderer renderer;
  s = renderer.init(pack, budget.bytes > 0 || pack.onDemand(), budget.bytes, Renderer::Streaming::kVisible);
  if (!s) return reportError(s);
  if (!quiet) warnIfModeFallsBack(renderer, pack, rs.mode);
  // Every view's tiles before any image is written: a tile that fails to decode leaves no image.
  if (s = loadViewTiles(renderer, cams, rs); !s) return reportError(s);
  std::vector<double> times;
  if (json) std::printf("{\"renderer\": \"%s\", \"views\": [", jsonEscape(ctx.renderer()).c_str());
  for (size_t i = 0; i < cams.size(); ++i) {
    FrameResult fr;
    uint64_t frames = 1;
    const unsigned readBack = kReadColor | (a.has("depth-out") ? kReadDepth : 0u);
    s = budget.bytes ? renderSettled(renderer, cams[i], rs, fr, readBack, frames) : renderer.render(cams[i], rs, fr, readBack);
    if (!s) return reportError(s);
    if (budget.bytes && !quiet && !json)
      std::fprintf(stderr, "%s: --gpu-budget: settled after %llu frames, %.1f MiB of tiles resident (%.1f MiB decoded in memory), %u cells %d level(s) coarser to fit\n",
                   outputs.images[i].c_str(), (unsigned long long)frames, fr.stats.residentBytes / 1048576.0,
                   fr.stats.heldBytes / 1048576.0, fr.stats.coarsened,
                   fr.stats.budgetBias);
    const std::string& image = outputs.images[i];
    s = writeImage(image, fr.color);
    if (!s) return reportError(s);
    if (a.has("depth-out")) {
      s = writePfm(outputs.depths[i], cams[i].width, cams[i].height, fr.depth);
      if (!s) return reportError(s);
    }
    times.push_back(fr.milliseconds);
    if (json) {
      std::printf("%s{\"file\": \"%s\", \"ms\": %.3f, \"cells\": %u, \"width\": %d, \"height\": %d}", i ? ", " : "",
                  jsonEscape(image).c_str(), fr.milliseconds, fr.cellsDrawn, cams[i].width, cams[i].height);
    } else if (!quiet) {
      std::fprintf(stderr, "%s: %dx%d, %u cells, %.1f ms\n", image.c_str(), cams[i].width, cams[i].height, fr.cellsDrawn,
                   fr.milliseconds);
    }
  }
  std::sort(times.begin(), times.end());
  // Tiles decoded: those the views draw (compressed pages), every tile (raw pages, mapped whole).
  const uint32_t tiles = pack.meta().cellCount, decoded = budget.bytes ? 0 : renderer.tilesResident();
  if (json) {
    std::printf("], \"median_ms\": %.3f", times[times.size() / 2]);
    if (!budget.bytes) std::printf(", \"tiles_decoded\": %u, \"tiles\": %u", decoded, tiles);
    std::printf("}\n");
  } else if (!quiet) {
    std::fprintf(stderr, "renderer: %s; median frame %.1f ms over %zu view(s)", ctx.renderer().c_str(),
                 times[times.size() / 2], times.size());
    if (!budget.bytes) std::fprintf(stderr, "; %u of %u tiles decoded", decoded, tiles);
    std::fprintf(stderr, "\n");
  }
  return 0;
}

}  // namespace sa
