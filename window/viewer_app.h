// `scanatlas view`: the interactive window (GLFW + Dear ImGui) around the one render core.
// Also runs scripted sessions (--script) so the window path is tested under xvfb in CI.
#pragma once
#include <cstdint>
#include <string>

#include "viewer/tile_cache.h"

namespace sa {

struct ViewerOptions {
  std::string scriptPath;        // commands to replay (see scanatlas view --help)
  std::string measurementsPath;  // where picks and measurements go (CSV); empty: stdout
  std::string groovesPath;       // a grooves JSON (scanatlas grooves): listed in the panel, drawn over the view
  int width = 1280, height = 800;
  bool vsync = true;
  bool quiet = false;
  GpuBudget gpuBudget;           // --gpu-budget (bytes 0: the whole atlas resident)
};

// Returns the process exit code (0 ok, 2 bad input, 1 internal); prints its own errors.
int runViewer(const std::string& packPath, const ViewerOptions& options);

extern const char* kViewerScriptHelp;

}  // namespace sa
