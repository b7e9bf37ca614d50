#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <sstream>

#include "atlas/pack_file.h"
#include "cli/args.h"
#include "cli/commands.h"
#include "modes/registry.h"
#include "common/fileio.h"
#include "formats/source.h"

namespace sa {
namespace {

// The NOTE line "texel: T wanted W[ capped by WHAT]" (packs made before it have none).
struct TexelNote {
  bool present = false;
  double wanted = 0;
  std::string cap;
};
TexelNote texelNote(const std::string& note) {
  TexelNote t;
  std::istringstream in(note);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("texel: ", 0) != 0) continue;
    double texel = 0;
    if (std::sscanf(line.c_str(), "texel: %lf wanted %lf", &texel, &t.wanted) != 2) continue;
    t.present = true;
    const size_t c = line.find(" capped by ");
    if (c != std::string::npos) t.cap = line.substr(c + 11);
  }
  return t;
}

// The NOTE line "precision: height-step T normal-tolerance D colour-tolerance L" (packs made
// before it have none: they kept every bit but the normals' low 6).
struct PrecisionNote {
  bool present = false;
  double step = 0, degrees = 0;
  int levels = 0;
};
PrecisionNote precisionNote(const std::string& note) {
  PrecisionNote p;
  std::istringstream in(note);
  std::string line;
  while (std::getline(in, line))
    if (std::sscanf(line.c_str(), "precision: height-step %lf normal-tolerance %lf colour-tolerance %d", &p.step,
                    &p.degrees, &p.levels) == 3)
      p.present = true;
  return p;
}

// The NOTE line "sparse-reach: R[ auto]" (only packs made with --sparse-reach have it).
struct ReachNote {
  double reach = 0;  // 0: none
  bool chosen = false;  // auto
};
ReachNote reachNote(const std::string& note) {
  ReachNote r;
  std::istringstream in(note);
  std::string line;
  while (std::getline(in, line))
    if (std::sscanf(line.c_str(), "sparse-reach: %lf", &r.reach) == 1) r.chosen = line.find(" auto") != std::string::npos;
  return r;
}

std::string fmtNumber(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

std::string precisionText(const PrecisionNote& p) {
  if (!p.present) return "not recorded (packed before the precision options: everything as computed)";
  if (p.step == 0 && p.degrees == 0 && p.levels == 0) return "lossless: heights, normals and colours as computed";
  return std::string("heights ") + (p.step > 0 ? "in steps of at most " + fmtNumber(p.step) + " texel" : "as computed") +
         ", normals " + (p.degrees > 0 ? "within " + fmtNumber(p.degrees) + " degree of the coder's prediction" : "as computed") +
         ", colours " + (p.levels > 0 ? "within " + std::to_string(p.levels) + " levels" : "as computed") +
         " (pack --lossless keeps all)";
}

// The page sections' stored bytes against their raw size (FORMAT.md, "Compressed pages").
struct PageBytes {
  const char* name;
  uint64_t stored = 0, raw = 0;
};
std::vector<PageBytes> pageBytes(const PackReader& pack) {
  const uint64_t texels = pack.pageTexels() * pack.meta().pageCount;
  const bool z = pack.compressedPages();
  std::vector<PageBytes> out;
  out.push_back({"heights", pack.section(z ? "HGTZ" : "HGHT").size(), texels * 2});
  if (pack.hasNormals()) out.push_back({"normals", pack.section(z ? "NRMZ" : "NRML").size(), texels * kNormalBytes});
  if (pack.hasColor()) out.push_back({"colour", pack.section(z ? "COLZ" : "COLR").size(), texels * 4});
  return out;
}

// The tiles' stored coarser levels (MIPZ): what they cost and what they are for.
std::string storedLevelsText() {
  std::string t;
  for (uint32_t l : kStoredLevels) t += (t.empty() ? "" : ", ") + std::to_string(l);
  return t;
}
void printStoredLevels(const PackReader& pack) {
  if (!pack.compressedPages()) return;
  const uint64_t bytes = pack.section("MIPZ").size();
  if (!bytes) {
    std::printf("mips      none stored (pack --no-levels, or an older scanatlas): a far view under --gpu-budget decodes whole tiles\n");
    return;
  }
  std::printf("mips      level %s of each tile stored (MIPZ), %.2f MiB, %.1f%% of the file: a far view decodes no tile\n",
              storedLevelsText().c_str(), double(bytes) / 1048576.0, 100.0 * double(bytes) / double(std::max<uint64_t>(1, pack.fileBytes())));
}

struct TexelRange {
  double min = 0, median = 0, max = 0;
};
TexelRange texelRange(std::vector<double> t) {
  if (t.empty()) return {};
  std::sort(t.begin(), t.end());
  return {t.front(), t[t.size() / 2], t.back()};
}

// Reads every point of one input (bounded memory) for counts, bounds and attribute ranges.
class InputStats : public BatchSink {
 public:
  Status onPoints(const PointBatch& b) override {
    for (size_t i = 0; i < b.size(); ++i) {
      const double p[3] = {b.x[i], b.y[i], b.z[i]};
      if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]))) {
        ++nonFinite;
        continue;
      }
      ++finite;
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], p[a]);
        hi[a] = std::max(hi[a], p[a]);
      }
      if (b.hasIntensity()) { iLo = std::min(iLo, b.intensity[i]); iHi = std::max(iHi, b.intensity[i]); }
      if (b.hasConfidence()) { cLo = std::min(cLo, b.confidence[i]); cHi = std::max(cHi, b.confidence[i]); }
      if (b.hasClassification()) ++classes[b.classification[i]];
    }
    return Status::ok();
  }
  Status onTriangles(const uint32_t*, size_t n) override {
    triangles += n;
    return Status::ok();
  }
  uint64_t finite = 0, nonFinite = 0, triangles = 0;
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  float iLo = INFINITY, iHi = -INFINITY, cLo = INFINITY, cHi = -INFINITY;
  std::map<int, uint64_t> classes;
};

int infoInputs(const std::vector<std::string>& paths, const std::string& columns, bool json) {
  if (json) std::printf("{\"inputs\": [");
  bool firstOut = true;
  for (const auto& path : paths) {
    auto in = InputSet::open({path}, columns);
    if (!in) {
      if (json) std::printf("]}\n");
      return reportError(in.status());
    }
    InputStats st;
    Status s = in->stream(st, in->hasTriangles());
    if (!s) {
      if (json) std::printf("]}\n");
      return reportError(s);
    }
    const InputFile& f0 = in->files()[0];
    std::string format = in->files().size() > 1 ? "scan set (" + std::to_string(in->files().size()) + " " +
                                                      formatName(f0.format) + " files)"
                                                : std::string(formatName(f0.format));
    std::string attrs;
    auto add = [&](bool on, const char* n) {
      if (on) attrs += std::string(attrs.empty() ? "" : ",") + n;
    };
    add(in->allHaveNormals(), "normals");
    add(in->anyHasColors(), "colors");
    add(in->allHaveIntensity(), "intensity");
    add(in->allHaveConfidence(), "confidence");
    add(in->allHaveClassification(), "classification");
    const uint64_t declared = in->pointCount();
    const uint64_t delivered = st.finite + st.nonFinite;
    const uint64_t holes = declared > delivered ? declared - delivered : 0;  // PCD NaN entries
    if (json) {
      std::printf("%s{\"file\": \"%s\", \"format\": \"%s\", \"detail\": \"%s\", \"declared_points\": %llu, "
                  "\"points\": %llu, \"invalid_entries\": %llu, \"nonfinite_points\": %llu, \"triangles\": %llu, "
                  "\"attributes\": \"%s\", \"bounds_min\": [%.17g, %.17g, %.17g], \"bounds_max\": [%.17g, %.17g, %.17g]",
                  firstOut ? "" : ", ", jsonEscape(path).c_str(), jsonEscape(format).c_str(), jsonEscape(f0.detail).c_str(),
                  (unsigned long long)declared, (unsigned long long)st.finite, (unsigned long long)holes,
                  (unsigned long long)st.nonFinite, (unsigned long long)st.triangles, attrs.c_str(), st.lo[0], st.lo[1],
                  st.lo[2], st.hi[0], st.hi[1], st.hi[2]);
      if (in->allHaveIntensity() && st.finite) std::printf(", \"intensity\": [%.9g, %.9g]", st.iLo, st.iHi);
      if (in->allHaveConfidence() && st.finite) std::printf(", \"confidence\": [%.9g, %.9g]", st.cLo, st.cHi);
      if (in->allHaveClassification()) {
        std::printf(", \"classes\": {");
        bool first = true;
        for (auto [c, n] : st.classes) {
          std::printf("%s\"%d\": %llu", first ? "" : ", ", c, (unsigned long long)n);
          first = false;
        }
        std::printf("}");
      }
      std::printf("}");
    } else {
      std::printf("input     %s\n", path.c_str());
      std::printf("format    %s%s%s\n", format.c_str(), f0.detail.empty() ? "" : ", ", f0.detail.c_str());
      std::printf("points    %llu", (unsigned long long)st.finite);
      if (holes) std::printf(" (%llu invalid entries of %llu skipped)", (unsigned long long)holes, (unsigned long long)declared);
      if (st.nonFinite) std::printf(" + %llu with NaN/Inf coordinates", (unsigned long long)st.nonFinite);
      if (st.triangles) std::printf(", %llu triangles", (unsigned long long)st.triangles);
      std::printf("\nattribs   %s\n", attrs.empty() ? "positions only" : ("positions," + attrs).c_str());
      std::printf("bounds    [%.12g, %.12g, %.12g] .. [%.12g, %.12g, %.12g]\n", st.lo[0], st.lo[1], st.lo[2], st.hi[0],
                  st.hi[1], st.hi[2]);
      if (in->allHaveIntensity() && st.finite) std::printf("intensity %.9g .. %.9g\n", st.iLo, st.iHi);
      if (in->allHaveConfidence() && st.finite) std::printf("confidence %.9g .. %.9g\n", st.cLo, st.cHi);
      if (in->allHaveClassification()) {
        std::printf("classes  ");
        for (auto [c, n] : st.classes) std::printf(" %d:%llu", c, (unsigned long long)n);
        std::printf("\n");
      }
      for (const auto& w : in->warnings()) std::printf("warning   %s\n", w.c_str());
      if (&path != &paths.back()) std::printf("\n");
    }
    firstOut = false;
  }
  if (json) std::printf("]}\n");
  return 0;
}

}  // namespace

// What info reports of a pack beyond its metadata: cells per level, their texels, page use.
struct PackSummary {
  std::map<int, uint32_t> perLevel;
  std::map<int, std::vector<double>> texelsPerLevel;  // each cell's texel: its box over its tile
  uint32_t forced = 0, degenerate = 0;
  uint64_t tileTexels = 0, pageTexels = 0;
  const char* upSource = "";
  double bmin[3], bmax[3];
  TexelNote tn;
};

const char* kPhases[6] = {"count", "distribute", "octree", "heightmaps", "write", "total"};

PackSummary summarize(const PackReader& pack) {
  const PackMeta& m = pack.meta();
  PackSummary r;
  for (const CellRecord& c : pack.cells()) {
    ++r.perLevel[c.level];
    r.texelsPerLevel[c.level].push_back((c.box[1] - c.box[0]) / std::max<uint16_t>(1, c.tileW));
    r.forced += (c.flags & kCellForced) != 0;
    r.degenerate += (c.flags & kCellDegenerate) != 0;
    r.tileTexels += uint64_t(c.tileW) * c.tileH;
  }
  r.pageTexels = pack.pageTexels() * m.pageCount;
  const char* upFrom[4] = {"unknown", "given", "format convention", "estimated from the data"};
  r.upSource = upFrom[std::min<uint32_t>(m.upSource, 3)];
  for (int i = 0; i < 3; ++i) {
    r.bmin[i] = m.origin[i] + m.boundsMin[i];
    r.bmax[i] = m.origin[i] + m.boundsMax[i];
  }
  r.tn = texelNote(pack.note());
  return r;
}

void printPackJson(const PackReader& pack, const PackSummary& sum) {
  const PackMeta& m = pack.meta();
  std::printf("{\"file\": \"%s\", \"bytes\": %llu, \"cells\": %u, \"forced_cells\": %u, \"degenerate_cells\": %u, "
              "\"levels\": {",
              jsonEscape(pack.path()).c_str(), (unsigned long long)pack.fileBytes(), m.cellCount, sum.forced, sum.degenerate);
  bool first = true;
  for (auto [l, n] : sum.perLevel) {
    std::printf("%s\"%d\": %u", first ? "" : ", ", l, n);
    first = false;
  }
  std::printf("}, \"texel_per_level\": {");
  first = true;
  for (auto& [l, t] : sum.texelsPerLevel) {
    const TexelRange r = texelRange(t);
    std::printf("%s\"%d\": [%.6g, %.6g, %.6g]", first ? "" : ", ", l, r.min, r.median, r.max);
    first = false;
  }
  std::printf("}, \"texels\": %llu, \"page_width\": %u, \"page_height\": %u, \"pages\": %u, \"atlas_occupancy\": %.4f, "
              "\"texel_size\": %.9g, \"sample_spacing\": %.9g, \"source_points\": %llu, \"skipped_points\": %llu, "
              "\"outliers_removed\": %llu, \"source_triangles\": %llu, \"color\": %s, \"normals\": %s, "
              "\"up\": [%.9g, %.9g, %.9g], \"up_source\": \"%s\", \"bytes_per_point\": %.3f, "
              "\"origin\": [%.17g, %.17g, %.17g], \"bounds_min\": [%.17g, %.17g, %.17g], "
              "\"bounds_max\": [%.17g, %.17g, %.17g], \"seconds\": {",
              (unsigned long long)sum.tileTexels, m.pageWidth, m.pageHeight, m.pageCount, double(sum.tileTexels) / double(sum.pageTexels),
              m.texelSize, m.sampleSpacing, (unsigned long long)m.sourcePoints, (unsigned long long)m.skippedPoints,
              (unsigned long long)m.outliersRemoved, (unsigned long long)m.sourceTriangles,
              pack.hasColor() ? "true" : "false", pack.hasNormals() ? "true" : "false", m.up[0], m.up[1], m.up[2],
              sum.upSource,
              double(pack.fileBytes()) / double(std::max<uint64_t>(1, m.sourcePoints)), m.origin[0], m.origin[1],
              m.origin[2], sum.bmin[0], sum.bmin[1], sum.bmin[2], sum.bmax[0], sum.bmax[1], sum.bmax[2]);
  for (int i = 0; i < 6; ++i) std::printf("%s\"%s\": %.3f", i ? ", " : "", kPhases[i], m.seconds[i]);
  std::printf("}, \"texel_wanted\": ");
  if (sum.tn.present) std::printf("%.9g", sum.tn.wanted);
  else std::printf("null");
  std::string capJson = "null";
  if (!sum.tn.cap.empty()) capJson = '"' + jsonEscape(sum.tn.cap) + '"';
  std::printf(", \"texel_capped_by\": %s", capJson.c_str());
  const PrecisionNote pn = precisionNote(pack.note());
  if (pn.present)
    std::printf(", \"precision\": {\"height_step\": %.9g, \"normal_tolerance\": %.9g, \"colour_tolerance\": %d}", pn.step,
                pn.degrees, pn.levels);
  else
    std::printf(", \"precision\": null");
  if (const ReachNote rn = reachNote(pack.note()); rn.reach > 0)
    std::printf(", \"sparse_reach\": {\"reach\": %.9g, \"auto\": %s}", rn.reach, rn.chosen ? "true" : "false");
  else
    std::printf(", \"sparse_reach\": null");
  std::printf(", \"pages_compressed\": %s, \"page_bytes\": {", pack.compressedPages() ? "true" : "false");
  first = true;
  for (const PageBytes& b : pageBytes(pack)) {
    std::printf("%s\"%s\": {\"stored\": %llu, \"raw\": %llu}", first ? "" : ", ", b.name,
                (unsigned long long)b.stored, (unsigned long long)b.raw);
    first = false;
  }
  std::printf("}");
  if (pack.compressedPages() && !pack.section("MIPZ").empty())
    std::printf(", \"stored_levels\": {\"levels\": [%s], \"bytes\": %llu}", storedLevelsText().c_str(),
                (unsigned long long)pack.section("MIPZ").size());
  else
    std::printf(", \"stored_levels\": null");
  std::printf(", \"modes\": [");
  bool firstMode = true;
  for (const ModeInfo& mi : allModes()) {
    const ModeSection ms = modeSection(pack, mi.mode);
    std::string section = "null";
    if (mi.sectionId) section = '"' + std::string(mi.sectionId, 4) + '"';
    std::printf("%s{\"mode\": \"%s\", \"section\": %s, \"present\": %s, \"bytes\": %llu, \"bake_s\": %.3f}",
                firstMode ? "" : ", ", mi.name, section.c_str(),
                !ms.needed || ms.present ? "true" : "false", (unsigned long long)ms.bytes, ms.bakeSeconds);
    firstMode = false;
  }
  std::printf("]}\n");
}

void printPackText(const PackReader& pack, const PackSummary& sum) {
  const PackMeta& m = pack.meta();
  std::printf("pack      %s (%.2f MiB, format version %u)\n", pack.path().c_str(), pack.fileBytes() / 1048576.0,
              kPackVersion);
  std::printf("source    %llu points (%llu NaN/Inf skipped, %llu outliers removed), %llu triangles, %s, %s, %s\n",
              (unsigned long long)m.sourcePoints, (unsigned long long)m.skippedPoints,
              (unsigned long long)m.outliersRemoved, (unsigned long long)m.sourceTriangles,
              (m.flags & kPackFromTriangles) ? "heights rasterized" : "heights by pull-push",
              pack.hasNormals() ? "stored normals" : "normals from height gradients",
              pack.hasColor() ? "with colour" : "no colour");
  std::printf("up        %.4g, %.4g, %.4g (%s)\n", m.up[0], m.up[1], m.up[2], sum.upSource);
  std::printf("bounds    [%.6f, %.6f, %.6f] .. [%.6f, %.6f, %.6f]\n", sum.bmin[0], sum.bmin[1], sum.bmin[2], sum.bmax[0], sum.bmax[1], sum.bmax[2]);
  std::printf("cells     %u (%u forced, %u degenerate), %u chunk(s)\n", m.cellCount, sum.forced, sum.degenerate, m.chunkCount);
  std::printf("levels   ");
  for (auto [l, n] : sum.perLevel) std::printf(" L%d:%u", l, n);
  std::printf("\n");
  std::printf("resolution");
  for (auto& [l, t] : sum.texelsPerLevel) std::printf(" L%d:%.4g", l, texelRange(t).median);
  std::printf(" (median texel per octree level");
  std::vector<double> all;
  for (auto& [l, t] : sum.texelsPerLevel) all.insert(all.end(), t.begin(), t.end());
  const TexelRange whole = texelRange(all);
  std::printf("; %.4g-%.4g over cells)\n", whole.min, whole.max);
  std::printf("texels    %llu in %u page(s) of %ux%u (occupancy %.1f%%), texel %.4g, sample spacing %.4g\n",
              (unsigned long long)sum.tileTexels, m.pageCount, m.pageWidth, m.pageHeight, 100.0 * double(sum.tileTexels) / double(sum.pageTexels),
              m.texelSize, m.sampleSpacing);
  if (!sum.tn.cap.empty())
    std::printf("detail    LOST: texels %.2fx coarser than the data's %.4g, capped by %s (repack with a larger --texels)\n",
                m.texelSize / sum.tn.wanted, sum.tn.wanted, sum.tn.cap.c_str());
  else if (sum.tn.present)
    std::printf("detail    full: the texels are the data's (median %.4g: half each cell's area spacing, or --texel-size)\n",
                sum.tn.wanted);
  std::printf("precision %s\n", precisionText(precisionNote(pack.note())).c_str());
  if (const ReachNote rn = reachNote(pack.note()); rn.reach > 0)
    std::printf("sparse    surface-like points reach up to %.3g sample spacings (--sparse-reach %s)\n", rn.reach,
                rn.chosen ? "auto" : fmtNumber(rn.reach).c_str());
  std::printf("bytes     %.2f per source point\n", double(pack.fileBytes()) / double(std::max<uint64_t>(1, m.sourcePoints)));
  std::printf("pages    ");
  uint64_t stored = 0, raw = 0;
  for (const PageBytes& b : pageBytes(pack)) {
    std::printf(" %s %.2f MiB (%.2fx)", b.name, double(b.stored) / 1048576.0, double(b.raw) / double(std::max<uint64_t>(1, b.stored)));
    stored += b.stored;
    raw += b.raw;
  }
  if (pack.compressedPages())
    std::printf("; coded per tile, %.2fx smaller than raw pages (%.2f MiB)\n", double(raw) / double(std::max<uint64_t>(1, stored)),
                double(raw) / 1048576.0);
  else
    std::printf("; raw (packed with --raw-pages or before compression)\n");
  printStoredLevels(pack);
  std::printf("timings  ");
  if (m.seconds[5] == 0) std::printf(" not recorded (packed with --reproducible)");
  for (int i = 0; i < 6 && m.seconds[5] != 0; ++i)
    if (i != 4) std::printf(" %s %.2fs", kPhases[i], m.seconds[i]);
  std::printf("\n");
  for (const ModeInfo& mi : allModes()) {
    const ModeSection ms = modeSection(pack, mi.mode);
    if (!ms.needed) std::printf("mode      %-9s ready (needs nothing baked)\n", mi.name);
    else if (!ms.problem.empty())
      std::printf("mode      %-9s unusable, draws %s: %s\n", mi.name, mi.fallback, ms.problem.c_str());
    else if (ms.present)
      std::printf("mode      %-9s section %.4s, %.2f MiB (%.2f bytes/texel), baked in %.2fs\n", mi.name, mi.sectionId,
                  double(ms.bytes) / 1048576.0, double(ms.bytes) / double(std::max<uint64_t>(1, sum.tileTexels)), ms.bakeSeconds);
    else
      std::printf("mode      %-9s not baked: draws %s (scanatlas bake %s --mode %s)\n", mi.name, mi.fallback,
                  pack.path().c_str(), mi.name);
  }
}

int cmdInfo(int argc, char** argv) {
  Args a;
  Status s = a.parse(argc, argv, {"columns"}, {"json", "help"}, {{"h", "help"}});
  if (a.flag("help")) {
    std::fputs("usage: scanatlas info PACK.hfa [--json]\n"
               "       scanatlas info INPUT... [--columns SPEC] [--json]\n\n"
               "For a pack: cells per octree level, texels, pages, bytes, bounds, the sample spacing\n"
               "and texel size, and how long each packing phase took.\n"
               "For input files (any format `pack` reads): the format and its details, the points\n"
               "(invalid PCD entries and NaN/Inf coordinates counted apart), triangles, attributes,\n"
               "exact bounds, intensity and confidence ranges and the points per class. Every point is\n"
               "read, in bounded memory.\n",
               stdout);
    return 0;
  }
  if (!s) return reportError(s);
  if (a.positionals().empty()) return reportError(Status::badInput("info: give a pack or input files (see --help)"));
  if (lowerExtension(a.positionals()[0]) != ".hfa") return infoInputs(a.positionals(), a.get("columns"), a.flag("json"));
  if (a.positionals().size() != 1) return reportError(Status::badInput("info: give exactly one pack (see --help)"));
  PackReader pack;
  s = pack.open(a.positionals()[0], PageLoad::kNone);  // metadata only: compressed pages stay coded
  if (!s) return reportError(s);
  const PackSummary summary = summarize(pack);
  if (a.flag("json")) printPackJson(pack, summary);
  else printPackText(pack, summary);
  return 0;
}

}  // namespace sa
