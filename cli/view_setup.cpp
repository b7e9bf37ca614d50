#include <cstdio>
#include "cli/view_setup.h"

#include <cstdlib>
#include <sstream>

#include "viewer/camera_path.h"

namespace sa {

std::vector<std::string> splitList(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

Status modesAndIterations(const Args& a, std::vector<RenderMode>& modes, std::vector<int>& iterations) {
  for (const auto& m : splitList(a.get("mode", "parallax"))) {
    auto r = parseMode(m);
    if (!r) return r.status();
    modes.push_back(*r);
  }
  for (const auto& t : splitList(a.get("iterations", std::to_string(kDefaultIterations)))) {
    auto r = parseInt("iterations", t, 1, 1024);
    if (!r) return r.status();
    iterations.push_back(int(*r));
  }
  if (modes.empty() || iterations.empty()) return Status::badInput("--mode and --iterations need at least one value");
  return Status::ok();
}

Status numberList(const Args& a, const std::string& opt, size_t count, std::vector<double>& out) {
  const auto items = splitList(a.get(opt));
  if (items.size() != count)
    return Status::badInput("--" + opt + ": expected " + std::to_string(count) + " comma-separated numbers");
  out.clear();
  for (const auto& i : items) {
    auto x = parseNumber(opt, i);
    if (!x) return x.status();
    out.push_back(*x);
  }
  return Status::ok();
}

void packBounds(const PackReader& pack, Eigen::Vector3d& lo, Eigen::Vector3d& hi) {
  const PackMeta& m = pack.meta();
  const Eigen::Vector3d origin(m.origin[0], m.origin[1], m.origin[2]);
  lo = origin + Eigen::Vector3d(m.boundsMin[0], m.boundsMin[1], m.boundsMin[2]);
  hi = origin + Eigen::Vector3d(m.boundsMax[0], m.boundsMax[1], m.boundsMax[2]);
}

Status camerasFromArgs(const Args& a, const PackReader& pack, int defaultOrbit, int defaultSize,
                       std::vector<Camera>& out) {
  Camera base;
  base.width = base.height = defaultSize;
  base.up = pack.viewUp();
  if (a.has("size")) SA_RETURN_IF_ERROR(parseWxH("size", a.get("size"), base.width, base.height));
  if (a.has("fov")) {
    auto v = parseNumber("fov", a.get("fov"));
    if (!v) return v.status();
    base.fovDeg = *v;
  }
  if (a.has("up")) {
    auto v = parseVec3("up", a.get("up"));
    if (!v) return v.status();
    if (v->norm() == 0) return Status::badInput("--up must not be zero");
    base.up = v->normalized();
  }
  Eigen::Vector3d lo, hi;
  packBounds(pack, lo, hi);
  const int given = int(a.has("path")) + int(a.has("orbit")) + int(a.has("eye"));
  if (given > 1) return Status::badInput("give one of --path, --orbit and --eye");
  if (a.has("path")) {
    auto cams = readCameraPath(a.get("path"), base.width, base.height);
    if (!cams) return cams.status();
    out = *cams;
    return Status::ok();
  }
  if (a.has("orbit") || (!a.has("eye") && defaultOrbit > 0)) {
    int n = defaultOrbit;
    if (a.has("orbit")) {
      auto v = parseInt("orbit", a.get("orbit"), 1, 100000);
      if (!v) return v.status();
      n = int(*v);
    }
    out = orbitCameras(lo, hi, n, base.up, base.fovDeg, base.width, base.height);
    if (a.has("zoom")) {
      auto z = parseNumber("zoom", a.get("zoom"));
      if (!z) return z.status();
      if (*z <= 0) return Status::badInput("--zoom must be positive");
      for (Camera& c : out) c.eye = c.target + (c.eye - c.target) / *z;
    }
    return Status::ok();
  }
  Camera c = orbitCameras(lo, hi, 1, base.up, base.fovDeg, base.width, base.height)[0];
  if (a.has("target")) {
    auto v = parseVec3("target", a.get("target"));
    if (!v) return v.status();
    c.target = *v;
  }
  if (a.has("eye")) {
    auto v = parseVec3("eye", a.get("eye"));
    if (!v) return v.status();
    c.eye = *v;
  }
  SA_RETURN_IF_ERROR(c.validate());
  out.push_back(c);
  return Status::ok();
}

Status loadViewTiles(Renderer& r, const std::vector<Camera>& cams, const RenderSettings& s) {
  for (const Camera& c : cams) SA_RETURN_IF_ERROR(r.loadVisibleTiles(c, s));
  return Status::ok();
}

void warnIfModeFallsBack(const Renderer& r, const PackReader& pack, RenderMode m) {
  if (m == RenderMode::kPoints || r.modeReady(m)) return;
  const ModeInfo& mi = modeInfo(m);
  if (!r.modeProblem(m).empty()) {
    std::fprintf(stderr, "scanatlas: warning: %s; drawing %s instead of the %s mode\n", r.modeProblem(m).c_str(),
                 modeName(r.drawnMode(m)), mi.name);
    return;
  }
  std::fprintf(stderr, "scanatlas: warning: %s has no %.4s section for the %s mode; drawing %s instead (bake it: "
               "scanatlas bake %s --mode %s)\n", pack.path().c_str(), mi.sectionId ? mi.sectionId : "----", mi.name,
               modeName(r.drawnMode(m)), pack.path().c_str(), mi.name);
}

Status modeSettingsFromArgs(const Args& a, RenderSettings& rs) {
  if (a.has("gdm-elsewhere")) {
    const std::string e = a.get("gdm-elsewhere");
    if (e != "exact" && e != "parallax") return Status::badInput("--gdm-elsewhere: exact or parallax, not '" + e + "'");
    rs.gdmParallaxElsewhere = e == "parallax";
  }
  if (a.has("auto-pixels")) {
    auto v = parseNumber("auto-pixels", a.get("auto-pixels"));
    if (!v) return v.status();
    if (!(*v >= 1 && *v <= 4096)) return Status::badInput("--auto-pixels must be between 1 and 4096");
    rs.autoPixels = *v;
  }
  if (!a.has("slices")) return Status::ok();
  if (a.get("slices") == "auto") {
    rs.slices = 0;
    return Status::ok();
  }
  auto v = parseInt("slices", a.get("slices"), 1, kMaxSlices);
  if (!v) return v.status();
  rs.slices = int(*v);
  return Status::ok();
}

Result<GpuBudget> gpuBudgetFor(const Args& a, const std::string& packPath) {
  GpuBudget b;
  if (a.has("gpu-budget")) {
    if (a.get("gpu-budget") == "off") return b;
    auto v = parseSize("gpu-budget", a.get("gpu-budget"));
    if (!v) return v.status();
    if (*v < (uint64_t(16) << 20)) return Status::badInput("--gpu-budget: at least 16M is needed (or off)");
    b.bytes = *v;
    return b;
  }
  b.automatic = true;
  b.ram = physicalMemoryBytes();
  if (const char* e = std::getenv("SCANATLAS_MEMORY")) {
    auto v = parseSize("SCANATLAS_MEMORY", e);
    if (!v) return v.status();
    b.ram = *v;
  }
  PackReader meta;
  SA_RETURN_IF_ERROR(meta.open(packPath, PageLoad::kNone));
  b.atlas = atlasBytes(meta);
  b.bytes = defaultGpuBudget(b.atlas, b.ram, 0);
  return b;
}

Status renderSettled(Renderer& r, const Camera& cam, const RenderSettings& rs, FrameResult& out, unsigned readBack,
                     uint64_t& frames, uint64_t maxFrames) {
  frames = 0;
  do {  // at least one frame: whether tiles are pending is known only once this view has been planned
    SA_RETURN_IF_ERROR(r.render(cam, rs, out, 0u));
    ++frames;
  } while (r.tilesPending() && frames < maxFrames);
  ++frames;
  return r.render(cam, rs, out, readBack);
}

}  // namespace sa
