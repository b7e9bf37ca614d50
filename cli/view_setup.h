// Camera options shared by render, bench and eval: --path, --orbit, --eye/--target/--up/--fov,
// --size.
#pragma once
#include <string>
#include <vector>

#include "atlas/pack_file.h"
#include "cli/args.h"
#include "viewer/camera.h"
#include "viewer/renderer.h"
#include "viewer/tile_cache.h"

namespace sa {

// defaultOrbit: views when neither --path nor --eye is given (0: one default view).
Status camerasFromArgs(const Args& a, const PackReader& pack, int defaultOrbit, int defaultSize,
                       std::vector<Camera>& out);
std::vector<std::string> splitList(const std::string& s);
// --mode LIST (default parallax) and --iterations LIST (default kDefaultIterations), as bench and eval take them.
Status modesAndIterations(const Args& a, std::vector<RenderMode>& modes, std::vector<int>& iterations);
// The modes' own settings, each when given: --slices N|auto (the slices mode's quads per cell;
// auto: 0), --auto-pixels P, --gdm-elsewhere exact|parallax.
Status modeSettingsFromArgs(const Args& a, RenderSettings& rs);
// --opt with exactly `count` comma-separated numbers.
Status numberList(const Args& a, const std::string& opt, size_t count, std::vector<double>& out);
void packBounds(const PackReader& pack, Eigen::Vector3d& lo, Eigen::Vector3d& hi);
// A renderer made with Renderer::Streaming::kVisible (a pack opened with PageLoad::kOnDemand,
// no GPU budget): every tile these views draw in these settings decoded and uploaded, before
// the first frame, so that a close-up of a large pack decodes only what it shows. The error of
// a tile that fails to decode names the file and the cell.
Status loadViewTiles(Renderer& r, const std::vector<Camera>& cams, const RenderSettings& s);
// Says on stderr when the pack lacks what mode m needs (and what draws instead, and how to bake it).
void warnIfModeFallsBack(const Renderer& r, const PackReader& pack, RenderMode m);

// --gpu-budget SIZE (suffixes K, M, G; at least 16M) or off (every tile resident); when not
// given, the default for the pack at packPath (defaultGpuBudget: a budget only where its pages
// outgrow the memory; SCANATLAS_MEMORY=SIZE stands in for this machine's RAM). Before GL: once
// a context exists, boundByGpuMemory (viewer/egl_context.h) adds what the GPU reports.
Result<GpuBudget> gpuBudgetFor(const Args& a, const std::string& packPath);
inline constexpr const char* kGpuBudgetHelp =
    "  --gpu-budget SIZE      keep at most SIZE of tiles on the GPU (suffixes K, M, G): each visible\n"
    "                         cell's tile at the level its texels on screen ask for (coarser where a\n"
    "                         texel is under a pixel; when the view does not fit, coarser except\n"
    "                         where it is largest on screen and still fits), tiles decoded in the\n"
    "                         background, the cells seen longest ago evicted first;\n"
    "                         parallax, slices, auto and points modes. Default: none while the pack's\n"
    "                         pages fit in a quarter of RAM and half the GPU's memory (where the\n"
    "                         driver reports it: NVIDIA, AMD), else the smaller of those; 'off'\n"
    "                         uploads every tile whatever its size. SCANATLAS_MEMORY=SIZE in the\n"
    "                         environment stands in for the machine's RAM\n";
// A frame of a streamed renderer once its tiles have settled for this view (frames rendered until
// none is pending, at most maxFrames); `frames` the frames it took.
Status renderSettled(Renderer& r, const Camera& cam, const RenderSettings& rs, FrameResult& out, unsigned readBack,
                     uint64_t& frames, uint64_t maxFrames = 100000);

}  // namespace sa
