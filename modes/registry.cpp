#include "modes/registry.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>

#include "modes/exact/exact.h"
#include "modes/gdm/gdm.h"
#include "modes/grooves/groove_bake.h"
#include "modes/grooves/groove_cast.h"
#include "modes/vdm/vdm.h"

namespace sa {
namespace {

Result<ExtraSection> bakeExact(const PackReader& pack, const BakeRequest&, std::string& summary) {
  double seconds = 0;
  ExtraSection s = exact::bakeSection(pack, &seconds);
  char line[160];
  std::snprintf(line, sizeof(line), "exact: section XMAX, %.1f MiB, baked in %.2f s", double(s.bytes.size()) / (1 << 20), seconds);
  summary = line;
  return s;
}

inline constexpr uint64_t kVdmDefaultBudget = uint64_t(256) << 20;

Result<ExtraSection> bakeVdm(const PackReader& pack, const BakeRequest& req, std::string& summary) {
  vdm::Selection sel;
  sel.clip = req.clip;
  sel.lo = req.lo;
  sel.hi = req.hi;
  sel.budget = req.budget ? req.budget : kVdmDefaultBudget;
  vdm::BakeReport rep;
  ExtraSection s = vdm::bakeSection(pack, sel, vdm::BakeOptions{}, rep, req.progress);
  char line[400];
  std::snprintf(line, sizeof(line),
                "vdm: section VDMF, %.1f MiB (budget %.0f MiB%s), %u of %u cells%s baked (%llu texels, %.1f B/texel, mean rank "
                "%.1f) in %.1f s%s",
                double(rep.bytes) / (1 << 20), double(sel.budget) / (1 << 20), req.budget ? "" : ", the default", rep.baked,
                rep.candidates, req.clip ? " in the clip box" : "", (unsigned long long)rep.texels,
                rep.texels ? double(rep.bytes) / double(rep.texels) : 0.0, rep.meanRank, rep.seconds,
                rep.overBudget ? (" - " + std::to_string(rep.overBudget) + " cells left out by the budget (they draw exact)").c_str()
                               : "");
  summary = line;
  return s;
}

Result<ExtraSection> bakeGdm(const PackReader& pack, const BakeRequest& req, std::string& summary) {
  const auto t0 = std::chrono::steady_clock::now();
  gdm::FunctionReport fr;
  const uint64_t budget = req.budget ? req.budget : gdm::kDefaultFunctionBudget;
  auto grids = gdm::buildForcedGrids(pack, budget, &fr, req.progress);
  if (!grids.isOk()) return grids.status();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ExtraSection s = gdm::makeSection(pack, *grids, seconds);
  uint64_t voxels = 0;
  size_t built = 0, functions = 0, rankSum = 0;
  double worstP95 = 0, kernelMin = 1e300, kernelMax = 0;
  for (const gdm::CellGrid& g : *grids) {
    if (g.nx > 0 && g.kernel > 0) {
      kernelMin = std::min(kernelMin, g.kernel);
      kernelMax = std::max(kernelMax, g.kernel);
    }
    voxels += g.voxelCount();
    built += g.nx > 0;
    functions += g.fn.rank > 0;
    rankSum += size_t(g.fn.rank);
    worstP95 = std::max(worstP95, g.fn.p95);
  }
  char kernel[96] = "";
  if (kernelMax > 0) std::snprintf(kernel, sizeof(kernel), ", surface kernel %.2f-%.2f sample spacings", kernelMin, kernelMax);
  char over[96] = "";
  if (fr.overBudget) std::snprintf(over, sizeof(over), ", %u more left out by the budget", fr.overBudget);
  char line[768];
  std::snprintf(line, sizeof(line),
                "gdm: section GDMV, %.1f MiB, %zu forced cells (%zu built, %zu with a direction function where rays skip "
                "%.0f voxels or more: %.1f MiB of the %.0f MiB budget%s, mean rank %.1f, p95 error up to %.2f voxels), "
                "%llu voxels%s, in %.1f s",
                double(s.bytes.size()) / (1 << 20), grids->size(), built, functions, gdm::kWorthAFunction,
                double(fr.bytes) / (1 << 20), double(budget) / (1 << 20), over, functions ? double(rankSum) / double(functions) : 0.0,
                worstP95, (unsigned long long)voxels, kernel, seconds);
  summary = line;
  return s;
}

const ModeInfo kModes[] = {
    {RenderMode::kParallax, "parallax", "linear search + bisection per height field (Lu, Low & Zheng); needs nothing baked",
     nullptr, nullptr, RenderMode::kParallax, nullptr, "parallax_cast.glsl"},
    {RenderMode::kExact, "exact",
     "min/max-mipmap traversal with the exact ray-patch root (Tevs et al. 2008); bakes XMAX (about 5.6 bytes a texel)",
     exact::kSectionId, bakeExact, RenderMode::kExact, "parallax", "exact.glsl"},
    {RenderMode::kVdm, "vdm",
     "view-dependent displacement (Wang et al. 2003): a per-texel distance per view direction, PCA-compressed, predict -> "
     "verify -> exact traversal; bakes VDMF for the cells in --clip-box or up to --budget (default 256M), and XMAX",
     vdm::kSectionId, bakeVdm, RenderMode::kExact, "exact", "vdm.glsl"},
    {RenderMode::kGdm, "gdm",
     "forced cells (not height fields: overhangs, thin parts) drawn from the implicit surface of their source points or "
     "triangles (signed distances at voxel corners) by a 3-D DDA from any face or from inside, guided by the "
     "SVD-compressed distance function (Wang et al. 2004); "
     "bakes GDMV (reads the pack's sources) and XMAX; other cells draw exact",
     gdm::kSectionId, bakeGdm, RenderMode::kExact, "exact", "gdm.glsl"},
    {RenderMode::kSlices, "slices",
     "volumetric texture slices (Meyer & Neyret 1998): --slices N quads per cell across the axis nearest the view, "
     "opaque under the height field (forced cells: inside gdm's implicit surface, when baked); needs nothing baked",
     nullptr, nullptr, RenderMode::kSlices, nullptr, nullptr, "slices_vs.glsl", "slices_fs.glsl"},
    {RenderMode::kAuto, "auto",
     "level of detail: per cell the parallax march where its box covers --auto-pixels pixels or more (default 8), "
     "slices where it covers fewer, as many as keep them a pixel apart along the view (depth error <= sqrt(3) pixel "
     "footprints, 004 §4.1); needs nothing baked",
     nullptr, nullptr, RenderMode::kAuto, nullptr, "parallax_cast.glsl"},
    {RenderMode::kGrooves, "grooves",
     "cracks and joints carved into the height field from their profiles (path-based surface detail, Bosch et al.): "
     "exact depth, facet normals, masking, shadows, anti-aliased under 2 pixels; bakes GROO from the grooves detected "
     "in the pack's sources (or --grooves FILE); a groove neither detected nor given is never drawn",
     gcast::kSectionId, grooves::bakeSection, RenderMode::kGrooves, "parallax", "grooves.glsl"},
    {RenderMode::kPoints, "points", "the source points as splats (the baseline; reads the pack's sources)", nullptr, nullptr,
     RenderMode::kPoints, nullptr, nullptr},
};
}  // namespace

std::span<const ModeInfo> allModes() { return kModes; }

const ModeInfo& modeInfo(RenderMode m) {
  for (const ModeInfo& i : kModes)
    if (i.mode == m) return i;
  return kModes[0];
}

const char* modeName(RenderMode m) { return modeInfo(m).name; }

std::string modeList() {
  std::string s;
  for (const ModeInfo& i : kModes) s += (s.empty() ? "" : ", ") + std::string(i.name);
  return s;
}

Result<RenderMode> parseMode(const std::string& name) {
  for (const ModeInfo& i : kModes)
    if (name == i.name) return i.mode;
  return Status::badInput("unknown mode '" + name + "' (modes: " + modeList() + ")");
}

ModeSection modeSection(const PackReader& pack, RenderMode m) {
  ModeSection s;
  const ModeInfo& i = modeInfo(m);
  if (!i.sectionId) return s;
  s.needed = true;
  if (m == RenderMode::kExact) {
    auto v = exact::readSection(pack);
    if (!v.isOk()) s.problem = v.status().message();
    if (v.isOk() && v->present) {
      s.present = true;
      s.bytes = v->bytes;
      s.bakeSeconds = v->bakeSeconds;
    }
  } else {
    // The sections with a header record: present, bytes, bake seconds alike.
    auto fill = [&](auto v) {
      if (!v.isOk()) s.problem = v.status().message();
      if (v.isOk() && v->present) {
        s.present = true;
        s.bytes = v->bytes;
        s.bakeSeconds = v->header.bakeSeconds;
      }
    };
    if (m == RenderMode::kGdm) fill(gdm::readSection(pack));
    else if (m == RenderMode::kGrooves) fill(gcast::readSection(pack));
    else if (m == RenderMode::kVdm) fill(vdm::readSection(pack));
  }
  return s;
}

Status bakeModes(const std::string& in, const std::string& out, const std::vector<RenderMode>& modes,
                 std::vector<std::string>& report, const BakeRequest& req) {
  PackReader pack;
  SA_RETURN_IF_ERROR(pack.open(in));
  std::vector<RenderMode> todo;
  for (RenderMode m : modes) {
    const ModeInfo& i = modeInfo(m);
    if (!i.bake) {
      report.push_back(std::string(i.name) + ": nothing to bake");
      continue;
    }
    // A mode's fallback section first, when the pack lacks it (vdm falls back to exact).
    if (i.needsMode != m && !modeSection(pack, i.needsMode).present &&
        std::find(todo.begin(), todo.end(), i.needsMode) == todo.end() &&
        std::find(modes.begin(), modes.end(), i.needsMode) == modes.end())
      todo.push_back(i.needsMode);
    if (std::find(todo.begin(), todo.end(), m) == todo.end()) todo.push_back(m);
  }
  std::vector<ExtraSection> add;
  for (RenderMode m : todo) {
    std::string line;
    auto section = modeInfo(m).bake(pack, req, line);
    if (!section.isOk()) return section.status();  // nothing is written (gdm: the sources are gone)
    add.push_back(std::move(*section));
    report.push_back(line);
  }
  if (add.empty() && in == out) return Status::ok();
  return rewritePackWithSections(pack, out, add);
}

}  // namespace sa
