// The one render core behind every front end (headless render now; window, bench and eval
// later): uploads a pack's pages and cell table, draws the cells' boxes instanced and
// ray-casts each height field per fragment. Needs a current OpenGL 4.5 core context.
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "atlas/pack_file.h"
#include "viewer/camera.h"
#include "viewer/image_io.h"

namespace sa {

const char* embeddedShader(std::string_view name);  // generated at build time

struct RenderSettings {
  int iterations = 12;   // linear search steps
  int refineSteps = 6;   // bisection steps after the linear search
  bool useColor = true;  // scan colour when the pack has it
  float background[3] = {0.1f, 0.1f, 0.12f};
  float baseColor[3] = {0.85f, 0.82f, 0.78f};
};

struct FrameResult {
  Image color;               // RGBA8, row 0 at the top
  std::vector<float> depth;  // linear view depth, row 0 at the top, +inf where nothing was hit
  double milliseconds = 0;   // draw + glFinish wall time
  uint32_t cellsDrawn = 0;
};

class Renderer {
 public:
  Renderer();
  ~Renderer();
  // Uploads the pack (the pack must outlive the renderer only during init()).
  Status init(const PackReader& pack);
  Status render(const Camera& cam, const RenderSettings& settings, FrameResult& out, bool readDepth);
  uint64_t gpuBytes() const { return gpuBytes_; }

 private:
  struct Gl;
  std::unique_ptr<Gl> gl_;
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d boundsMin_, boundsMax_;
  uint32_t cellCount_ = 0;
  bool hasColor_ = false;
  uint64_t gpuBytes_ = 0;
};

}  // namespace sa
