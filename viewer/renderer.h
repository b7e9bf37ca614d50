// The one render core behind every front end (headless render, bench, eval; the window
// later): uploads a pack's pages and cell table, culls and orders the cells' boxes on the
// CPU, draws them instanced and ray-casts each height field per fragment. The `points`
// baseline draws the source points as splats. Needs a current OpenGL 4.5 core context.
#pragma once
#include <cstdint>
#include <chrono>
#include <memory>
#include <array>
#include <string>
#include <vector>

#include "atlas/pack_file.h"
#include "modes/registry.h"
#include "viewer/camera.h"
#include "viewer/culling.h"
#include "viewer/image_io.h"
#include "viewer/tile_cache.h"

namespace sa {
namespace gcast {
struct SectionView;
}

const char* embeddedShader(std::string_view name);  // generated at build time


enum class Shading { kLambert = 0, kNormals = 1, kHeight = 2 };

struct ClipSettings {
  bool box = false;  // keep only what lies inside [lo, hi] (world coordinates)
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();
  bool plane = false;  // keep only the side the normal points to
  Eigen::Vector3d point = Eigen::Vector3d::Zero(), normal = Eigen::Vector3d::UnitZ();
};

inline constexpr int kMaxSlices = 1024;
inline constexpr int kAutoSlices = 64;  // slices auto: at most this many a cell (modes/slices/slices_vs.glsl)

struct RenderSettings {
  RenderMode mode = RenderMode::kParallax;
  Shading shading = Shading::kLambert;
  bool edl = false;          // eye-dome lighting post pass
  float edlStrength = 1.0f;
  float edlRadius = 1.5f;    // pixels
  bool showBoxes = false;    // cell boxes as wireframes coloured by orientation
  bool headLight = true;     // else a fixed light from lightDir (world, toward the light)
  Eigen::Vector3d lightDir = Eigen::Vector3d(0.3, 1, 0.5);
  Eigen::Vector3d up = Eigen::Vector3d::UnitY();  // axis of the height colour ramp
  ClipSettings clip;
  int iterations = kDefaultIterations;  // linear search steps (the bound when steps are adaptive)
  int refineSteps = 6;   // bisection steps after the linear search
  bool useColor = true;  // scan colour when the pack has it
  float background[3] = {0.1f, 0.1f, 0.12f};
  float baseColor[3] = {0.85f, 0.82f, 0.78f};
  CullOptions cull;      // what a frame may skip (all on by default)
  bool countWork = false;  // read the work counters back (FrameStats::work); costs atomics per fragment
  int slices = 16;         // slices mode: quads per cell (1..kMaxSlices; 0: auto, per cell from its distance)
  int sliceAxis = -1;      // slices mode: -1 the axis nearest the view, per cell; 0, 1, 2: u, v or w always
  // auto mode: boxes whose projected diameter is under this many pixels are drawn as slices
  // (auto count, at most the next power of two of it), the others by the parallax march.
  double autoPixels = 8;
  // Self-shadowing (001 §3.2): a second cast from each hit toward the light (lightDir; needs
  // headLight off), within the hit's cell, by the mode's own cast (vdm: a lookup).
  bool shadows = false;
  // grooves mode: grooves under two pixels wide are anti-aliased over the pixel's footprint, the
  // part of it that lands inside the groove by this many rays (off: one ray per pixel, as wide
  // grooves). 4 give 0.006 mean luminance error against 16-sample supersampling at 0.3 pixels
  // (GroovesGl.NarrowGroovesAreAntiAliasedLikeSupersampling), 8 the same.
  bool grooveAA = true;
  int grooveSamples = 4;
  // gdm mode: the cells that are height fields (no voxel grid) are drawn by parallax's programs
  // (the march, iterations) instead of exact's traversal: gdm then differs from parallax only in
  // the forced cells (whose rays that pass no voxel near the samples still take exact).
  bool gdmParallaxElsewhere = false;
};

// Per-frame work of the surface casts (RenderSettings::countWork): a ray is one fragment's cast;
// work is the mode's unit (parallax: height samples; exact: pyramid nodes visited).
struct WorkCounters {
  bool valid = false;
  uint64_t rays = 0, work = 0, hits = 0, capped = 0;
  // The mode's precomputed-function lookups (vdm: at the top face; gdm: where a ray enters a
  // forced cell), those that fell back to the traversal, and misses settled without it.
  uint64_t lookups = 0, fallbacks = 0, fastMisses = 0;
  uint32_t max = 0, p50 = 0, p90 = 0, p99 = 0;  // percentiles of work per ray (255 = 255 or more)
  std::vector<uint64_t> histogram;               // rays per work 0..255 (the last: 255 or more)
  double mean() const { return rays ? double(work) / double(rays) : 0; }
  // Adds another frame's counts (percentiles recomputed from the summed histogram).
  void add(const WorkCounters& o);
  void percentiles();
};

struct FrameStats {
  uint32_t submitted = 0, culled = 0, drawn = 0, inside = 0, splats = 0;
  uint32_t sliced = 0;         // auto mode: boxes drawn as slices
  uint32_t missing = 0;        // streamed packs: visible cells not drawn, their tiles not resident yet
  // --gpu-budget: levels uploaded this frame, cells evicted, visible cells drawn coarser than their
  // texels ask to fit the budget (by budgetBias levels), bytes of the cache in use, bytes of
  // decoded levels held in memory.
  uint32_t uploads = 0, evicted = 0, coarsened = 0;
  int budgetBias = 0;
  uint64_t residentBytes = 0, heldBytes = 0;
  uint64_t points = 0;         // points mode: points drawn
  // grooves: pixels the first pass left to the carved cast (near a groove), and those it drew as
  // the height field because both of their slots held other cells (grooves_defer.glsl).
  uint64_t deferred = 0, undeferred = 0;
  double cpuMs = 0;            // culling + submission + glFinish, wall clock
  double gpuMs = -1;           // GL_TIME_ELAPSED of the draws (-1 when unavailable)
  uint64_t fragments = 0;      // fragment shader invocations (or samples passed, see below)
  bool fragmentsAreInvocations = false;
  RenderMode drawnMode = RenderMode::kParallax;  // a pack without a mode's section draws its fallback
  WorkCounters work;
};

enum ReadBack : unsigned { kReadColor = 1, kReadDepth = 2, kReadNormals = 4, kReadCells = 8, kReadShadow = 16 };

struct FrameResult {
  Image color;                // RGBA8, row 0 at the top
  std::vector<float> depth;   // linear view depth, row 0 at the top, +inf where nothing was hit
  std::vector<float> normals; // xyz per pixel (world), zero where nothing was hit
  std::vector<uint32_t> cells; // the index + 1 of the cell that drew the pixel, 0 where none (kReadCells)
  std::vector<uint8_t> shadowed; // 1 where the pixel's point is in its cell's own shadow (kReadShadow, settings.shadows)
  FrameStats stats;
  double milliseconds = 0;    // == stats.cpuMs
  uint32_t cellsDrawn = 0;    // boxes ray-cast (front + inside)
};

class Renderer {
 public:
  Renderer();
  ~Renderer();
  // Uploads the pack. streamPages: allocate the atlas, then decode (a pack opened with
  // PageLoad::kOnDemand) and upload its tiles in the background, the visible cells nearest the
  // camera first, up to 64 MiB a frame; a cell whose tile is not resident yet is not drawn (a
  // window shows its first image at once, whatever the pack's size). The reader must then
  // outlive the renderer. Without streamPages the pack's pages must be in memory (PageLoad::kAll).
  // gpuBudget (bytes, needs streamPages): the page textures are a cache of that size, each
  // visible cell's tile resident at the level its projected texels ask for (a level-0 texel
  // under kMaxTexelPx pixels: a coarser level), all visible cells coarser still when they do not fit;
  // cells not seen for longest are evicted. Tiles are decoded as the view asks for them and
  // memory holds only their levels on the GPU and coarser, so the pack is best opened with
  // PageLoad::kTiles (no page memory: packs larger than RAM). Draws parallax, slices, auto and points.
  // streaming (streamPages without gpuBudget): kWholePack decodes every tile in the background,
  // the visible cells first (a window); kVisible decodes only the tiles of the views given to
  // loadVisibleTiles before they are rendered, so a close-up of a large pack decodes what it
  // shows (a cell not loaded so is not drawn).
  enum class Streaming { kWholePack, kVisible };
  Status init(const PackReader& pack, bool streamPages = false, uint64_t gpuBudget = 0,
              Streaming streaming = Streaming::kWholePack);
  // The modes a --gpu-budget renderer draws as themselves (the others fall back to parallax).
  static bool budgetMode(RenderMode m) {
    return m == RenderMode::kParallax || m == RenderMode::kSlices || m == RenderMode::kAuto || m == RenderMode::kPoints;
  }
  // Streamed packs: tiles are still on their way (--gpu-budget: the last frame lacked a visible
  // cell or a cell's wanted level, or uploaded one).
  bool tilesPending() const;
  uint32_t tilesResident() const;  // cells whose tiles are on the GPU
  // Blocks until every tile is decoded, then uploads them all (a streamed render that must be whole).
  void waitForTiles();
  // Streamed without a budget: decodes and uploads every tile this view draws (kWholePack: all
  // of them), so that a render of it is the image of a whole upload; an error names the file and
  // the tile that failed to decode. Nothing to do for a pack uploaded whole or under a budget.
  Status loadVisibleTiles(const Camera& cam, const RenderSettings& s);
  // The first tile that failed to decode while streaming ("" when none): its cell never draws.
  std::string streamError() const;
  // The points baseline: positions relative to the pack origin (xyz floats), RGBA8 colours.
  Status setPoints(const std::vector<float>& xyz, const std::vector<uint8_t>& rgba, double spacing);
  bool hasPoints() const { return pointCount_ > 0; }
  // Whether this pack can draw mode m as itself (its section is present), else what it draws.
  bool modeReady(RenderMode m) const;
  RenderMode drawnMode(RenderMode m) const;
  // Why mode m's section could not be used (an older version, a corrupt section), "" when it could
  // or the pack has none: the mode then draws its fallback; the other modes are unaffected.
  const std::string& modeProblem(RenderMode m) const { return modeProblems_[int(m)]; }
  uint64_t modeGpuBytes(RenderMode m) const;
  Status render(const Camera& cam, const RenderSettings& settings, FrameResult& out, unsigned readBackMask);
  Status render(const Camera& cam, const RenderSettings& settings, FrameResult& out, bool readDepth) {
    return render(cam, settings, out, kReadColor | (readDepth ? kReadDepth : 0u));
  }
  // Linear depth at pixel (x, y from the top) of the last frame; +inf where nothing was hit.
  float depthAt(int x, int y) const;
  // Copies the last frame to the default framebuffer (window front ends).
  void present(int width, int height) const;
  uint64_t gpuBytes() const { return gpuBytes_; }
  uint64_t pointBytes() const { return pointCount_ * 16; }
  double nearPlane() const;

 private:
  struct FrameUniforms {
    float hi[3], lo[3];
    double nearPlane = 0;
    Eigen::Matrix3f rot;
    Eigen::Matrix4f proj;
    Eigen::Vector3f fwd, up, light, clipLo, clipHi, right, camUp;
    Eigen::Vector4f plane;
    float heightLo = 0, heightHi = 0;
    float pixelAngle = 0;  // vertical field of view over the height in pixels (radians)
    // The ray through framebuffer position (x, y) (world, camera-relative): rayBase + rayDx x + rayDy y.
    Eigen::Vector3f rayBase, rayDx, rayDy;
  };
  void uploadPages(const PackReader& pack);
  unsigned pageTexture(unsigned format, bool present, const uint8_t* fill, unsigned fillFormat, uint32_t w, uint32_t h,
                       uint32_t layers);
  std::string maskDefines() const;
  Status initBudget(const PackReader& pack, uint64_t budget, int maxLayers);
  void uploadLevel(const TileResidency::Upload& u);
  bool planBudget(const Camera& cam, const Eigen::Vector3d& camRel, const VisibleSet& vis, FrameStats& st);
  void takeLevels();
  void trimLevels(const TileResidency::Frame& plan);
  void dropLevels(uint32_t cell, uint32_t from);
  void uploadTiles(uint64_t budgetBytes);
  Status ensureTargets(int width, int height);
  CullOptions cullOptions(const RenderSettings& s) const;
  void uploadVisibility(const Camera& cam, const Eigen::Vector3d& camRel, double nearPlane, const RenderSettings& s,
                        VisibleSet& vis, FrameStats& st);
  // render()'s steps: the visible set (with the budget's plan or the streamer's wants), the
  // drawn mode's storage buffers, the cleared targets, and the frame's timings once drawn.
  Status prepareVisible(const Camera& cam, const RenderSettings& s, const Eigen::Vector3d& camRel, double np, VisibleSet& vis,
                        FrameStats& st);
  void bindModeBuffers(RenderMode drawn);
  void clearTargets(const Camera& cam, const RenderSettings& s, unsigned readBackMask);
  void finishTimings(FrameStats& st, std::chrono::steady_clock::time_point t0);
  FrameUniforms frameUniforms(const Camera& cam, const RenderSettings& s, const Eigen::Vector3d& camRel, double np) const;
  void setCommonUniforms(unsigned program, const FrameUniforms& f, const RenderSettings& s) const;
  void drawCells(const VisibleSet& vis, const FrameUniforms& f, const RenderSettings& s, const unsigned* bufs);
  void beginGrooves(const RenderSettings& s, unsigned frontProgram, unsigned insideProgram);
  Status ensureShadowPrograms(RenderMode m);
  void drawDeferredGrooves(const FrameUniforms& f, const RenderSettings& s, bool wantNormals, bool wantCells);
  void depthFromLinear(const FrameUniforms& f);
  Status createDeferTargets(int width, int height);
  void readDeferred(FrameStats& st);
  Status initModes(const PackReader& pack);
  Status initGrooves(const PackReader& pack, const gcast::SectionView& v, bool& usable);
  void readCounters(WorkCounters& w);
  void drawPoints(const Camera& cam, const FrameUniforms& f, const RenderSettings& s, FrameStats& st);
  void drawEdl(const RenderSettings& s);
  void readBack(const Camera& cam, unsigned what, FrameResult& out);
  struct Gl;
  std::unique_ptr<Gl> gl_;
  std::unique_ptr<CellCuller> culler_;
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d boundsMin_, boundsMax_;
  uint32_t cellCount_ = 0;
  bool hasColor_ = false, hasNormals_ = false;
  bool coverMasks_ = false;  // --gpu-budget: coarse levels with coverage masks (maskDefines)
  uint64_t gpuBytes_ = 0, pointCount_ = 0, exactBytes_ = 0, vdmBytes_ = 0, gdmBytes_ = 0, grooveBytes_ = 0;
  std::string modeProblems_[kRenderModes];
  // A mode's shader costs llvmpipe on every pixel of every box it draws, taken branches or not, so
  // a box gets the least program that draws it exactly: per cell, grooves 0 (none: parallax's
  // programs) or 1 (the two passes of grooves_defer.glsl).
  std::vector<uint8_t> grooveKind_;
  std::vector<uint8_t> gdmKind_;     // per cell: 2 a voxel grid (forced), 0 none
  // The boxes a mode's own programs draw, apart from those parallax's draw (grooves; gdm with
  // parallax elsewhere): grooves' front and inside, then gdm's front and inside.
  std::vector<DrawItem> ownLists_[4];
  // The frame's draw lists in upload order (their offsets in the item buffer follow it).
  std::array<const std::vector<DrawItem>*, 8> drawOrder(const VisibleSet& vis) const;
  double spacing_ = 0;
};

}  // namespace sa
