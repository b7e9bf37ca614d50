#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <thread>

#include "cli/args.h"
#include "cli/commands.h"
#include "cli/progress.h"
#include "cli/view_setup.h"
#include "common/fileio.h"
#include "modes/registry.h"
#include "preprocess/cluster.h"
#include "preprocess/pipeline.h"

namespace sa {
namespace {

const char* kHelp =
    "usage: scanatlas pack INPUT... -o OUT.hfa [options]\n"
    "\n"
    "Converts scans into a height-field atlas pack. Inputs, several and mixed: PLY (ascii or\n"
    "binary, points or meshes), Stanford .conf scan sets (range scans aligned by their\n"
    "transforms), PCD (ascii, binary, binary_compressed; NaN entries of organized clouds\n"
    "skipped), Draco .drc (clouds and meshes), LAS 1.0-1.4 (LAZ must be decompressed first),\n"
    "OBJ/OFF/STL meshes and text clouds (.xyz, .pts, .csv, .txt). Memory stays within\n"
    "--mem-budget whatever the input size (points go through on-disk chunks; a point input that\n"
    "fits one chunk stays in memory), except that PCD binary_compressed and Draco files are\n"
    "decoded whole and meshes are held in memory.\n"
    "\n"
    "On a cluster: mpirun -np N scanatlas pack ... (or srun --mpi=pmix under Slurm) splits the\n"
    "chunks' normals, octree and height maps over N ranks; rank 0 reads, distributes and writes.\n"
    "The inputs, the output's directory and --scratch must be on a filesystem every rank sees.\n"
    "The pack is the one a single process makes, byte for byte with --reproducible. Ranks on one\n"
    "machine share its cores.\n"
    "\n"
    "options:\n"
    "  -o, --output FILE      the pack to write (written atomically: FILE appears only when complete)\n"
    "  --mem-budget SIZE      working memory for points in flight (default 1G; suffixes K, M, G)\n"
    "  --texels N             cap on the texels over all height maps (default: none beyond 8 per\n"
    "                         input point); a cap that makes texels coarser than the data's is\n"
    "                         reported (summary, 'info': lost detail)\n"
    "  --texel-size X         one texel size for every cell, in input units (default: per cell, half\n"
    "                         its points' median area spacing, within 4x of the pack's either way)\n"
    "  --max-depth N          deepest octree level (default 10; the paper uses 6-10)\n"
    "  --max-angle DEG        height-field test: largest angle between a normal and the cell's\n"
    "                         plane normal (default 85; the paper's test is 90)\n"
    "  --coverage R           a texel is empty unless its surface point lies within R sample\n"
    "                         spacings of an input point (in 3-D: holes, scan edges and height\n"
    "                         jumps such as roof to ground stay open) (default 1.5)\n"
    "  --fill-gaps R          point inputs: a gap inside a cell's height map is closed when every\n"
    "                         texel of it lies within R coverage radii of surface: the gaps a\n"
    "                         random scatter of points leaves, which look like pinholes from\n"
    "                         afar (default 2; 0 keeps every gap open, for small real holes)\n"
    "  --sparse-reach R|auto  point inputs: a point whose neighbours lie on a clean surface (not\n"
    "                         loose returns such as foliage, not a scan's edge) lets its splat and\n"
    "                         coverage follow its own spacing up to R times the pack's, so a surface\n"
    "                         sampled much more sparsely than the rest (a terrestrial scan's far\n"
    "                         field, a strip flown higher, water) is drawn as surface instead of\n"
    "                         specks (default 1.5, the limit of every point, which leaves sparse\n"
    "                         water returns open; 6 covers regions 16x sparser; at most 16).\n"
    "                         auto: R is the median spacing of the surface-like points sampled\n"
    "                         over 3 of the pack's spacings apart (1.5 when there are none); the\n"
    "                         summary and 'info' say what it chose.\n"
    "                         The surface test is the smoothing fit's: not with --no-smooth on\n"
    "                         files with normals\n"
    "  --splat R              point inputs: each point spreads over R sample spacings with a\n"
    "                         smooth kernel (default 1.5; 0 = bilinear onto the nearest texels)\n"
    "  --no-smooth            point inputs: keep the points where they are (default: moved onto\n"
    "                         their moving-least-squares surface where the neighbourhood is one,\n"
    "                         which averages out the noise of merged scans; the fit's normals\n"
    "                         replace the file's). With normals in the file it skips the fit\n"
    "                         and keeps them: about 1.2x faster\n"
    "  --outlier-ratio F      point inputs: a point whose mean distance to its 8 nearest\n"
    "                         neighbours is F times the median of its neighbours' is removed as an\n"
    "                         outlier (default 3; 0 keeps every point)\n"
    "  --up X,Y,Z             the scan's up axis, stored in the pack as every view's default\n"
    "                         (default: the format's convention - LAS +z, Stanford scan sets +y,\n"
    "                         an organized PCD's camera -y refined to its floor or table - else\n"
    "                         from the data, e.g. terrain's thin axis, else +y; STL +z)\n"
    "  --outliers F           fraction of a cell's points whose normal may fail the test (default\n"
    "                         0.01 for points, whose estimated normals are noisy; 0, the paper's\n"
    "                         strict test, for meshes, where a failing vertex is a fold)\n"
    "  --min-split N          cells with fewer points are not split further (default 32 for points;\n"
    "                         4 for meshes, whose faces must all pass the test)\n"
    "  --neighbours K         neighbours for normal estimation when the input has none (default 24)\n"
    "  --columns LIST         text inputs: what each column is (x,y,z,nx,ny,nz,r,g,b,i,c,confidence; _ skips);\n"
    "                         default: the header line, or by count (3 xyz, 4 xyzi, 6 xyzrgb,\n"
    "                         7 xyzirgb as PTS, 9 xyzrgb+normals); delimiter detected\n"
    "  --as-points            ignore mesh faces: build height maps from the vertices by pull-push\n"
    "  --strict               a NaN or infinite coordinate is an error (default: skipped, counted)\n"
    "  --force                repack even if OUT already holds a pack of the same input and options\n"
    "                         (checked by a hash of the points as read, the options and the file sizes, stored in the pack)\n"
    "  --scratch DIR          where temporary chunk files go (default: beside the output; the coded\n"
    "                         tiles wait beside the output until they are copied into it)\n"
    "  --modes LIST           also bake what these surface-detail modes need (comma-separated):\n"
    "                         exact (min/max mipmaps, ~5.6 bytes a texel), vdm (view-dependent\n"
    "                         distances for the cells within its default 256M budget, and exact's),\n"
    "                         gdm (implicit surfaces of the forced cells from the sources, and exact's);\n"
    "                         parallax and points need nothing. Later, with a region or a budget:\n"
    "                         scanatlas bake OUT.hfa --mode vdm --clip-box ... | --budget SIZE\n"
    "  --raw-pages            store the atlas pages uncompressed (larger; mapped in place, no decoding\n"
    "                         when opened). Default: each tile coded losslessly (prediction + zstd)\n"
    "                         after the precision below is applied\n"
    "  --no-levels            do not store each tile's level 4 (a 16th of its texels along each side)\n"
    "                         beside it (MIPZ: 3.4 % of the 20 M-point survey's pack, 5.7 % of\n"
    "                         autzen's; about 5 % more packing time). Without it a far view under\n"
    "                         --gpu-budget decodes whole tiles to build its coarse levels (the survey's\n"
    "                         overview at 512x512: every cell drawn after 16.0 s instead of 3.8 s)\n"
    "  --zstd-level N         zstd level of the coded tiles, 1..19 (default 6; 1 packs the 2 M-point\n"
    "                         survey 8 % faster and 5 % larger, 9 is 2 % smaller and slower still;\n"
    "                         decoding costs the same at any level)\n"
    "  --height-step T        heights rounded to steps of at most T texels; a height moves by half\n"
    "                         a step at most (default 1/16 for points, whose heights are averages\n"
    "                         of noisy samples; 0, all 16 bits of the code kept, for meshes)\n"
    "  --normal-tolerance DEG a stored normal may move by up to DEG degrees to what the coarser\n"
    "                         texels around it predict, which the page coder then stores as\n"
    "                         nothing (default 1.5 for points; 0, every normal kept, for meshes)\n"
    "  --colour-tolerance L   the same for colours, in grey levels per channel (default 4; 0 keeps)\n"
    "  --lossless             --height-step 0 --normal-tolerance 0 --colour-tolerance 0: the pages\n"
    "                         hold the heights, normals and colours as computed (larger)\n"
    "  --reproducible         no timings in the pack: the same input and options give the same bytes\n"
    "                         (timings stay in the summary)\n"
    "  --json                 print the summary as JSON on stdout\n"
    "  -q, --quiet            no progress and no summary\n";


// Bakes the sections of `modes` the pack at `path` lacks (an up-to-date pack may hold them).
// Grooves given in a file are baked again whenever given (the file may have been edited).
Status bakeMissingModes(const std::string& path, const std::vector<RenderMode>& modes, const BakeRequest& req, bool quiet) {
  PackReader pack;
  SA_RETURN_IF_ERROR(pack.open(path, PageLoad::kNone));  // which sections are there: no pages decoded
  std::vector<RenderMode> missing;
  for (RenderMode m : modes) {
    const ModeSection ms = modeSection(pack, m);
    const bool again = m == RenderMode::kGrooves && !req.groovesFile.empty();
    if (ms.needed && (!ms.present || again) && std::find(missing.begin(), missing.end(), m) == missing.end())
      missing.push_back(m);
  }
  if (missing.empty()) return Status::ok();
  std::vector<std::string> report;
  SA_RETURN_IF_ERROR(bakeModes(path, path, missing, report, req));
  if (!quiet)
    for (const std::string& r : report) std::fprintf(stderr, "baked %s\n", r.c_str());
  return Status::ok();
}

const char* upSourceName(uint32_t s) {
  const char* names[4] = {"unknown", "given", "the format's convention", "estimated from the data"};
  return names[std::min<uint32_t>(s, 3)];
}

}  // namespace

// --height-step, --normal-tolerance, --colour-tolerance and --lossless.
static Status parsePrecision(const Args& a, PackOptions& opt) {
  const bool lossless = a.flag("lossless");
  for (const char* name : {"height-step", "normal-tolerance", "colour-tolerance"})
    if (lossless && a.has(name)) return Status::badInput(std::string("--lossless and --") + name + " do not go together");
  if (lossless) {
    opt.heightStep = opt.normalTolerance = 0;
    opt.colourTolerance = 0;
  }
  if (a.has("height-step")) {
    auto v = parseNumber("height-step", a.get("height-step"));
    if (!v) return v.status();
    if (*v < 0 || *v > 1) return Status::badInput("--height-step must be in [0, 1] (texels)");
    opt.heightStep = *v;
  }
  if (a.has("normal-tolerance")) {
    auto v = parseNumber("normal-tolerance", a.get("normal-tolerance"));
    if (!v) return v.status();
    if (*v < 0 || *v > 10) return Status::badInput("--normal-tolerance must be in [0, 10] (degrees)");
    opt.normalTolerance = *v;
  }
  if (a.has("colour-tolerance")) {
    auto v = parseInt("colour-tolerance", a.get("colour-tolerance"), 0, 64);
    if (!v) return v.status();
    opt.colourTolerance = static_cast<int>(*v);
  }
  return Status::ok();
}

// The options that shape the pack (not the output or the modes).
static Status parsePackOptions(const Args& a, PackOptions& opt) {
  if (a.has("mem-budget")) {
    auto v = parseSize("mem-budget", a.get("mem-budget"));
    if (!v) return v.status();
    if (*v < (16u << 20)) return (Status::badInput("--mem-budget: at least 16M is needed"));
    opt.memBudget = *v;
  }
  if (a.has("texels")) {
    auto v = parseSize("texels", a.get("texels"));
    if (!v) return v.status();
    if (*v < 1024 || *v > (uint64_t(1) << 34)) return (Status::badInput("--texels: must be between 1K and 16G"));
    opt.texelBudget = *v;
  }
  if (a.has("texel-size")) {
    auto v = parseNumber("texel-size", a.get("texel-size"));
    if (!v) return v.status();
    if (*v <= 0) return (Status::badInput("--texel-size must be positive"));
    opt.texelSize = *v;
  }
  if (a.has("max-depth")) {
    auto v = parseInt("max-depth", a.get("max-depth"), 0, 20);
    if (!v) return v.status();
    opt.octree.maxDepth = static_cast<int>(*v);
  }
  if (a.has("max-angle")) {
    auto v = parseNumber("max-angle", a.get("max-angle"));
    if (!v) return v.status();
    if (*v <= 0 || *v > 90) return (Status::badInput("--max-angle must be in (0, 90]"));
    opt.octree.maxAngleDeg = *v;
  }
  if (a.has("coverage")) {
    auto v = parseNumber("coverage", a.get("coverage"));
    if (!v) return v.status();
    if (*v <= 0 || *v > 100) return (Status::badInput("--coverage must be in (0, 100]"));
    opt.coverageRadius = *v;
  }
  if (a.has("sparse-reach") && a.get("sparse-reach") == "auto") {
    opt.sparseReachAuto = true;
  } else if (a.has("sparse-reach")) {
    auto v = parseNumber("sparse-reach", a.get("sparse-reach"));
    if (!v || *v < 1.5 || *v > kMaxSparseReach)
      return Status::badInput("--sparse-reach must be 'auto' or a number in [1.5, 16], not '" + a.get("sparse-reach") + "'");
    opt.sparseReach = *v;
  }
  if (a.has("fill-gaps")) {
    auto v = parseNumber("fill-gaps", a.get("fill-gaps"));
    if (!v) return v.status();
    if (*v < 0 || *v > 100) return (Status::badInput("--fill-gaps must be in [0, 100]"));
    opt.gapReach = *v;
  }
  if (a.has("outliers")) {
    auto v = parseNumber("outliers", a.get("outliers"));
    if (!v) return v.status();
    if (*v < 0 || *v > 0.5) return (Status::badInput("--outliers must be in [0, 0.5]"));
    opt.octree.outlierFraction = *v;
  }
  if (a.has("min-split")) {
    auto v = parseInt("min-split", a.get("min-split"), 1, 1 << 30);
    if (!v) return v.status();
    opt.octree.minSplitPoints = static_cast<uint32_t>(*v);
  }
  if (a.has("neighbours")) {
    auto v = parseInt("neighbours", a.get("neighbours"), 3, 128);
    if (!v) return v.status();
    opt.normalNeighbours = static_cast<int>(*v);
  }
  if (a.has("splat")) {
    auto v = parseNumber("splat", a.get("splat"));
    if (!v) return v.status();
    if (*v < 0 || *v > 100) return (Status::badInput("--splat must be in [0, 100]"));
    opt.splatRadius = *v;
  }
  if (a.has("outlier-ratio")) {
    auto v = parseNumber("outlier-ratio", a.get("outlier-ratio"));
    if (!v) return v.status();
    if (*v != 0 && *v < 1.5) return (Status::badInput("--outlier-ratio must be 0 (off) or at least 1.5"));
    opt.outlierRatio = *v;
  }
  if (a.has("up")) {
    auto v = parseVec3("up", a.get("up"));
    if (!v) return v.status();
    if (!(v->norm() > 0)) return (Status::badInput("--up must not be zero"));
    opt.up = v->normalized();
  }
  opt.smooth = !a.flag("no-smooth");
  opt.asPoints = a.flag("as-points");
  opt.strict = a.flag("strict");
  opt.force = a.flag("force");
  opt.reproducible = a.flag("reproducible");
  opt.compressPages = !a.flag("raw-pages");
  opt.storeLevels = !a.flag("no-levels");
  if (a.has("zstd-level")) {
    auto v = parseNumber("zstd-level", a.get("zstd-level"));
    if (!v) return v.status();
    if (!(*v >= 1 && *v <= kMaxTileLevel && *v == std::floor(*v)))
      return Status::badInput("--zstd-level must be a whole number from 1 to " + std::to_string(kMaxTileLevel));
    opt.pageLevel = int(*v);
  }
  SA_RETURN_IF_ERROR(parsePrecision(a, opt));
  opt.scratchParent = a.get("scratch");
  return Status::ok();
}

// The summary: JSON on stdout, or text on stderr.
static void printSummary(const std::string& out, const PackSummary& sum, const PackOptions& opt, bool json) {
  const bool autoReach = opt.sparseReachAuto, reachGiven = sum.sparseReach > 0 && opt.sparseReachGiven();
  const double mpts = sum.seconds[5] > 0 ? sum.pointsRead / sum.seconds[5] / 1e6 : 0;
  const unsigned cores = sum.threads ? sum.threads : std::max(1u, std::thread::hardware_concurrency());
  // MPI ranks poll while they wait for each other: their waits count as busy.
  const std::string ranks = sum.ranks > 1 ? " over " + std::to_string(sum.ranks) + " MPI ranks" : "";
  auto busy = [&](int phase) { return sum.seconds[phase] > 0 ? sum.cpuSeconds[phase] / sum.seconds[phase] : 0.0; };
  if (sum.upToDate && !json)
    std::fprintf(stderr, "%s is up to date (same points, files and options, hash %016llx, checked in %.2fs); --force repacks\n",
                 out.c_str(), (unsigned long long)sum.inputHash, sum.seconds[5]);
  if (json) {
    std::printf("{\"output\": \"%s\", \"points\": %llu, \"skipped_points\": %llu, \"triangles\": %llu, \"cells\": %u, "
                "\"forced_cells\": %u, \"degenerate_cells\": %u, \"layered_cells\": %u, \"outliers_removed\": %llu, "
                "\"surface_samples\": %llu, "
                "\"chunks\": %u, \"chunks_in_memory\": %u, \"pages\": %u, \"page_width\": %u, \"page_height\": %u, "
                "\"texels\": %llu, \"texel_size\": %.9g, \"texel_min\": %.9g, \"texel_max\": %.9g, \"sample_spacing\": %.9g, \"area_spacing\": %.9g, \"up\": [%.9g, %.9g, %.9g], "
                "\"up_source\": \"%s\", \"bytes\": %llu, "
                "\"bytes_per_point\": %.3f, \"scratch_bytes\": %llu, \"scratch_raw_bytes\": %llu, \"scratch_coded_bytes\": %llu, \"up_to_date\": %s, \"normals_estimated\": %s, \"from_triangles\": %s, \"color\": %s, "
                "\"sparse_reach\": %.9g, \"sparse_surface_share\": %.9g, \"cells_per_level\": [",
                jsonEscape(out).c_str(), (unsigned long long)sum.pointsRead, (unsigned long long)sum.pointsSkipped,
                (unsigned long long)sum.triangles, sum.cells, sum.forcedCells, sum.degenerateCells, sum.layeredCells,
                (unsigned long long)sum.outliersRemoved, (unsigned long long)sum.surfaceSamples, sum.chunks, sum.chunksHeld, sum.pages, sum.pageWidth, sum.pageHeight,
                (unsigned long long)sum.texels, sum.texelSize, sum.texelMin, sum.texelMax, sum.spacing, sum.areaSpacing, sum.up.x(), sum.up.y(), sum.up.z(),
                upSourceName(sum.upSource),
                (unsigned long long)sum.fileBytes, double(sum.fileBytes) / double(std::max<uint64_t>(1, sum.pointsRead)),
                (unsigned long long)sum.scratchBytes, (unsigned long long)sum.scratchRawBytes,
                (unsigned long long)sum.codedScratchBytes, sum.upToDate ? "true" : "false", sum.normalsEstimated ? "true" : "false", sum.fromTriangles ? "true" : "false",
                sum.hasColor ? "true" : "false", sum.sparseReach, sum.sparseSurfaceShare);
    for (size_t i = 0; i < sum.cellsPerLevel.size(); ++i) std::printf("%s%u", i ? ", " : "", sum.cellsPerLevel[i]);
    std::printf("], \"seconds\": {\"count\": %.3f, \"distribute\": %.3f, \"octree\": %.3f, \"heightmaps\": %.3f, "
                "\"write\": %.3f, \"total\": %.3f}, ",
                sum.seconds[0], sum.seconds[1], sum.seconds[2], sum.seconds[3], sum.seconds[4], sum.seconds[5]);
    std::printf("\"cpu_seconds\": {\"count\": %.3f, \"distribute\": %.3f, \"octree\": %.3f, \"heightmaps\": %.3f, "
                "\"write\": %.3f, \"total\": %.3f}, \"cores\": %u, \"ranks\": %u, \"mpts_per_s\": %.3f}\n",
                sum.cpuSeconds[0], sum.cpuSeconds[1], sum.cpuSeconds[2], sum.cpuSeconds[3], sum.cpuSeconds[4],
                sum.cpuSeconds[5], cores, sum.ranks, mpts);
  } else if (!sum.upToDate) {
    std::fprintf(stderr,
                 "packed %s: %llu points%s%s -> %u cells (%u forced, %u of them layered), %u chunk(s)%s\n"
                 "  texels %llu (texel %.4g, %.4g-%.4g over cells; spacing %.4g) in %u page(s) of %ux%u, %s%s\n"
                 "  up %.3g,%.3g,%.3g (%s)\n"
                 "  file %.1f MiB (%.1f bytes/point), temporary files %.1f MiB written (chunks %.1f, coded tiles %.1f)\n"
                 "  time %.2fs (count %.2f, distribute %.2f, normals+octree %.2f, heightmaps %.2f, write %.2f) = %.2f Mpts/s\n"
                 "  cores busy %.2f of %u%s (count %.2f, distribute %.2f, normals+octree %.2f, heightmaps %.2f, write %.2f)\n",
                 out.c_str(), (unsigned long long)sum.pointsRead,
                 sum.pointsSkipped ? (" (" + std::to_string(sum.pointsSkipped) + " NaN/Inf skipped)").c_str() : "",
                 sum.outliersRemoved ? (" (" + std::to_string(sum.outliersRemoved) + " outliers removed)").c_str() : "",
                 sum.cells, sum.forcedCells, sum.layeredCells, sum.chunks, sum.chunksHeld ? " held in memory" : "",
                 (unsigned long long)sum.texels, sum.texelSize,
                 sum.texelMin, sum.texelMax, sum.spacing, sum.pages, sum.pageWidth, sum.pageHeight,
                 sum.fromTriangles ? "heights rasterized from triangles" : "heights by pull-push",
                 sum.normalsEstimated ? ", normals estimated" : "", sum.up.x(), sum.up.y(), sum.up.z(),
                 upSourceName(sum.upSource), sum.fileBytes / 1048576.0,
                 double(sum.fileBytes) / double(std::max<uint64_t>(1, sum.pointsRead)),
                 (sum.scratchBytes + sum.codedScratchBytes) / 1048576.0, sum.scratchBytes / 1048576.0,
                 sum.codedScratchBytes / 1048576.0, sum.seconds[5], sum.seconds[0],
                 sum.seconds[1], sum.seconds[2], sum.seconds[3], sum.seconds[4], mpts, busy(5),
                 cores, ranks.c_str(), busy(0), busy(1), busy(2), busy(3), busy(4));
    if (reachGiven && sum.sparseSurfaceShare > 0)
      std::fprintf(stderr, "  sparse reach %.3g (%s%.2g %% of the points on surfaces sampled over 3 sample spacings apart)\n",
                   sum.sparseReach, autoReach ? "auto: the median spacing of the " : "", 100 * sum.sparseSurfaceShare);
    else if (reachGiven)
      std::fprintf(stderr, "  sparse reach %.3g (no points on surfaces sampled over 3 sample spacings apart)\n", sum.sparseReach);
  }
}

int cmdPack(int argc, char** argv) {
  Args a;
  Status s = a.parse(argc, argv,
                     {"output", "mem-budget", "texels", "texel-size", "max-depth", "max-angle", "coverage", "sparse-reach", "fill-gaps",
                      "neighbours", "scratch", "outliers", "min-split", "columns", "splat", "outlier-ratio", "up", "modes", "grooves",
                      "height-step", "normal-tolerance", "colour-tolerance", "zstd-level"},
                     {"as-points", "strict", "force", "no-smooth", "reproducible", "raw-pages", "no-levels", "lossless", "json", "quiet", "help"},
                     {{"o", "output"}, {"q", "quiet"}, {"h", "help"}});
  if (a.flag("help")) {
    std::fputs(kHelp, stdout);
    return 0;
  }
  if (!s) return reportError(s);
  if (a.positionals().empty()) return reportError(Status::badInput("pack: no input files (see --help)"));
  if (!a.has("output")) return reportError(Status::badInput("pack: -o OUT.hfa is required"));
  PackOptions opt;
  s = parsePackOptions(a, opt);
  if (!s) return reportError(s);
  std::vector<RenderMode> modes;
  for (const std::string& m : splitList(a.get("modes"))) {
    auto r = parseMode(m);
    if (!r) return reportError(Status::badInput("--modes: " + r.status().message()));
    modes.push_back(*r);
  }
  BakeRequest bake;
  if (a.has("grooves")) {
    bake.groovesFile = a.get("grooves");
    if (!std::filesystem::is_regular_file(bake.groovesFile))
      return reportError(Status::badInput("--grooves: " + bake.groovesFile + ": no such file"));
    if (std::find(modes.begin(), modes.end(), RenderMode::kGrooves) == modes.end()) modes.push_back(RenderMode::kGrooves);
  }
  for (int i = 0; i < argc; ++i) opt.commandLine += std::string(i ? " " : "") + argv[i];
  const std::string out = a.get("output");
  if (std::filesystem::is_directory(out)) return reportError(Status::badInput(out + ": is a directory; give a file name"));

  // Under mpirun or srun the ranks share the work; only rank 0 reports.
  s = Cluster::start();
  if (!s) return reportError(s);
  struct ClusterStop {
    ~ClusterStop() { Cluster::stop(); }
  } clusterStop;
  const bool root = Cluster::rank() == 0;
  auto fail = [&](const Status& e) { return root ? reportError(e) : (e.kind() == ErrorKind::kBadInput ? 2 : 1); };
  auto input = InputSet::open(a.positionals(), a.get("columns"));
  if (!input) return fail(input.status());
  s = checkNotAnInput(out, input->allPaths(), "-o");
  if (!s) return fail(s);
  const bool quiet = a.flag("quiet") || !root;
  for (const auto& w : input->warnings())
    if (!quiet) std::fprintf(stderr, "scanatlas: warning: %s\n", w.c_str());
  Progress progress(!quiet && !a.flag("json"));
  PackSummary sum;
  s = packInput(*input, out, opt, [&](const char* p, uint64_t d, uint64_t t) { progress(p, d, t); }, sum);
  progress.finish();
  if (!s) return fail(s);
  if (!root) return 0;
  s = bakeMissingModes(out, modes, bake, quiet || a.flag("json"));
  if (!s) return reportError(s);
  for (size_t i = input->warnings().size(); i < sum.warnings.size(); ++i)
    if (!quiet) std::fprintf(stderr, "scanatlas: warning: %s\n", sum.warnings[i].c_str());
  if (a.flag("json") || !quiet) printSummary(out, sum, opt, a.flag("json"));
  return 0;
}

}  // namespace sa
