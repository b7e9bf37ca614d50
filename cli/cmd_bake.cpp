// scanatlas bake: adds what a surface-detail mode needs to an existing pack (modes/registry.h).
#include <cstdio>

#include "cli/args.h"
#include "cli/commands.h"
#include "cli/progress.h"
#include "cli/view_setup.h"
#include "common/fileio.h"
#include "modes/registry.h"

namespace sa {

int cmdBake(int argc, char** argv) {
  Args a;
  Status s = a.parse(argc, argv, {"mode", "output", "clip-box", "budget", "grooves"}, {"force", "quiet", "help"},
                     {{"o", "output"}, {"q", "quiet"}, {"h", "help"}});
  if (a.flag("help")) {
    std::printf("usage: scanatlas bake PACK --mode LIST [-o OUT] [--clip-box X0,Y0,Z0,X1,Y1,Z1] [--budget SIZE] [--grooves FILE] [--force]\n\n"
                "Bakes what the listed surface-detail modes need into the pack: their optional sections\n"
                "(docs/FORMAT.md), checksummed like the rest. The pack is rewritten atomically (a complete\n"
                "new file replaces it, or goes to OUT); its cells, pages and hash are unchanged. A mode whose\n"
                "section is already there is skipped unless --force. Baking runs on every core.\n"
                "  --clip-box ...   vdm: only the cells whose box meets this box (world coordinates)\n"
                "  --budget SIZE    vdm: the section's bytes never exceed SIZE (default 256M; suffixes K, M, G);\n"
                "                   cells are taken in pack order while their worst case still fits.\n"
                "                   gdm: the direction functions' bytes never exceed SIZE (default 32M); the\n"
                "                   cells whose rays would skip most voxels get theirs first (the surfaces\n"
                "                   themselves are always baked)\n"
                "  --grooves FILE   grooves: store these (a grooves JSON: exported, edited or drawn by hand;\n"
                "                   those with a depth as they are, the others measured in the sources' points)\n"
                "                   instead of detecting them in the sources\n"
                "Modes:\n");
    for (const ModeInfo& m : allModes()) std::printf("  %-9s %s\n", m.name, m.summary);
    return 0;
  }
  if (!s) return reportError(s);
  if (a.positionals().size() != 1) return reportError(Status::badInput("bake: give exactly one pack (see --help)"));
  if (!a.has("mode")) return reportError(Status::badInput("bake: --mode LIST is required (modes: " + modeList() + ")"));
  const std::string in = a.positionals()[0];
  const std::string out = a.has("output") ? a.get("output") : in;
  PackReader pack;
  s = pack.open(in);
  if (!s) return reportError(s);
  std::vector<RenderMode> todo;
  const bool quiet = a.flag("quiet");
  for (const std::string& name : splitList(a.get("mode"))) {
    auto m = parseMode(name);
    if (!m) return reportError(Status::badInput("--mode: " + m.status().message()));
    const ModeSection ms = modeSection(pack, *m);
    if (!ms.needed) {
      if (!quiet) std::fprintf(stderr, "%s: needs nothing baked\n", name.c_str());
      continue;
    }
    if (ms.present && !a.flag("force") && out == in && !(*m == RenderMode::kGrooves && a.has("grooves"))) {
      if (!quiet) std::fprintf(stderr, "%s: already baked (%.1f MiB, %.2f s); --force bakes it again\n", name.c_str(),
                               double(ms.bytes) / (1 << 20), ms.bakeSeconds);
      continue;
    }
    todo.push_back(*m);
  }
  if (todo.empty() && out == in) return 0;
  BakeRequest req;
  if (a.has("clip-box")) {
    std::vector<double> n;
    s = numberList(a, "clip-box", 6, n);
    if (!s) return reportError(s);
    req.clip = true;
    req.lo = Eigen::Vector3d(std::min(n[0], n[3]), std::min(n[1], n[4]), std::min(n[2], n[5]));
    req.hi = Eigen::Vector3d(std::max(n[0], n[3]), std::max(n[1], n[4]), std::max(n[2], n[5]));
  }
  if (a.has("budget")) {
    auto v = parseSize("budget", a.get("budget"));
    if (!v) return reportError(v.status());
    if (*v < (1u << 16)) return reportError(Status::badInput("--budget: at least 64K"));
    req.budget = *v;
  }
  if (a.has("grooves")) req.groovesFile = a.get("grooves");
  Progress progress(!quiet, "bake", "cells");
  req.progress = [&](uint64_t done, uint64_t total) { progress("cells", done, total); };
  std::vector<std::string> report;
  s = bakeModes(in, out, todo, report, req);
  progress.finish();
  if (!s) return reportError(s);
  if (!quiet)
    for (const std::string& r : report) std::fprintf(stderr, "baked %s -> %s\n", r.c_str(), out.c_str());
  return 0;
}

}  // namespace sa
