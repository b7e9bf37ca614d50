#include "modes/registry.h"

#include <cstdio>
#include <cstring>

#include "modes/exact/exact.h"

namespace sa {
namespace {

ExtraSection bakeExact(const PackReader& pack, double* seconds) { return exact::bakeSection(pack, seconds); }

const ModeInfo kModes[] = {
    {RenderMode::kParallax, "parallax", "linear search + bisection per height field (Lu, Low & Zheng); needs nothing baked",
     nullptr, nullptr, nullptr, "parallax_cast.glsl"},
    {RenderMode::kExact, "exact",
     "maximum-mipmap traversal with the exact ray-patch root (Tevs et al. 2008); bakes XMAX (about 2/3 of the heights' bytes)",
     exact::kSectionId, bakeExact, "parallax", "exact.glsl"},
    {RenderMode::kPoints, "points", "the source points as splats (the baseline; reads the pack's sources)", nullptr, nullptr,
     nullptr, nullptr},
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
    if (v.isOk() && v->present) {
      s.present = true;
      s.bytes = v->bytes;
      s.bakeSeconds = v->bakeSeconds;
    }
  }
  return s;
}

Status bakeModes(const std::string& in, const std::string& out, const std::vector<RenderMode>& modes,
                 std::vector<std::string>& report) {
  PackReader pack;
  SA_RETURN_IF_ERROR(pack.open(in));
  std::vector<ExtraSection> add;
  for (RenderMode m : modes) {
    const ModeInfo& i = modeInfo(m);
    if (!i.bake) {
      report.push_back(std::string(i.name) + ": nothing to bake");
      continue;
    }
    double seconds = 0;
    add.push_back(i.bake(pack, &seconds));
    char line[160];
    std::snprintf(line, sizeof(line), "%s: section %.4s, %.1f MiB, baked in %.2f s", i.name, i.sectionId,
                  double(add.back().bytes.size()) / (1 << 20), seconds);
    report.push_back(line);
  }
  if (add.empty() && in == out) return Status::ok();
  return rewritePackWithSections(pack, out, add);
}

}  // namespace sa
