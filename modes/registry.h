// The surface-detail modes: one table. A mode is a bake (optional, versioned, checksummed pack
// sections, written only when asked: `pack --modes`, `scanatlas bake`), a shader unit (the
// renderer's per-mode cast function, viewer/shaders or modes/<name>/) and a CPU reference.
// Adding a mode: a folder under modes/ and one line in kModes (modes/registry.cpp).
#pragma once
#include <functional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "atlas/pack_file.h"
#include "common/error.h"

namespace sa {

enum class RenderMode { kParallax = 0, kExact = 1, kPoints = 2, kVdm = 3, kGdm = 4, kSlices = 5, kAuto = 6, kGrooves = 7 };
inline constexpr int kRenderModes = 8;

// What a bake may be limited to (modes that bake per cell: vdm) and how it reports progress.
struct BakeRequest {
  bool clip = false;  // only cells whose box meets [lo, hi] (world coordinates)
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();
  uint64_t budget = 0;  // bytes the section may take (0: the mode's default)
  // grooves: a grooves JSON (edited, or drawn by hand) instead of detecting them in the sources;
  // grooves with a depth are taken as they are, the others measured in the points.
  std::string groovesFile;
  std::function<void(uint64_t done, uint64_t total)> progress;
};

struct ModeInfo {
  RenderMode mode;
  const char* name;
  const char* summary;      // one line for --help and info
  const char* sectionId;    // the section its bake writes, null when it needs none
  // Builds the section from a pack (null when nothing is baked); summary: one line for the user.
  Result<ExtraSection> (*bake)(const PackReader& pack, const BakeRequest& req, std::string& summary);
  RenderMode needsMode;      // a mode whose section this one also needs (its own mode when none)
  const char* fallback;     // what a pack without the section draws instead
  const char* castUnit;     // the shader unit defining castCell (embedded by name), null for points
  // Modes that draw their own geometry instead of casting in cell boxes (slices): their vertex
  // and fragment shaders (embedded by name); null for the others.
  const char* vertexShader = nullptr;
  const char* fragmentShader = nullptr;
};

std::span<const ModeInfo> allModes();
const ModeInfo& modeInfo(RenderMode m);
const char* modeName(RenderMode m);
Result<RenderMode> parseMode(const std::string& name);
// "parallax, exact, points": for messages and --help.
std::string modeList();

// What a pack holds for a mode: whether its section is there, its bytes and bake seconds.
struct ModeSection {
  bool needed = false;   // the mode has a bake
  bool present = false;
  uint64_t bytes = 0;
  double bakeSeconds = 0;
  std::string problem;   // the section is there but unusable (older version, corrupt): why
};
ModeSection modeSection(const PackReader& pack, RenderMode m);

// Bakes `modes` for the pack at `in` and writes the pack with their sections to `out`
// (atomically; may equal `in`). Modes without a bake are skipped; report gets a line per mode.
Status bakeModes(const std::string& in, const std::string& out, const std::vector<RenderMode>& modes,
                 std::vector<std::string>& report, const BakeRequest& req = {});

}  // namespace sa
