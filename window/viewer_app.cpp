#include "window/viewer_app.h"

#include "viewer/egl_context.h"

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <vector>

#include "atlas/pack_file.h"
#include "viewer/camera_controller.h"
#include "viewer/camera_path.h"
#include "viewer/renderer.h"
#include "viewer/source_points.h"
#include "window/script.h"
#include "common/fileio.h"
#include "grooves/grooves.h"
#include "modes/grooves/groove_bake.h"

namespace sa {

const char* kViewerScriptHelp =
    "Script commands (one per line, '#' comments; each runs on its own frame; the whole script\n"
    "is checked before the window opens):\n"
    "  size W H                       resize the window\n"
    "  camera EX EY EZ TX TY TZ [UX UY UZ [FOV]]   set the camera (world coordinates)\n"
    "  orbit DX DY | pan DX DY        drag by pixels (orbit about the pivot)\n"
    "  zoom PX PY FACTOR              zoom toward pixel (PX, PY); FACTOR < 1 moves closer\n"
    "  frame | top | front | side     frame all / preset views\n"
    "  pick PX PY                     pick the surface at a pixel (added to the measurement)\n"
    "  distance | polyline | height   report the last two picks' distance, the polyline length\n"
    "                                 over all picks, the last two picks' height difference\n"
    "  clear                          forget the picks\n"
    "  clip box X0 Y0 Z0 X1 Y1 Z1 | clip plane PX PY PZ NX NY NZ | clip off\n"
    "  shading lambert|normals|height|color | edl on|off | boxes on|off | iterations N\n"
    "  screenshot FILE.png [W H]      the current view, at window resolution or W x H (.png or .jpg)\n"
    "  windowshot FILE.png            the whole window, panel included\n"
    "  bookmark                       append the camera to PACK.views.json\n"
    "  groove N                       select groove N of --grooves and fly to it (logged with its\n"
    "                                 width, depth, length and centre)\n"
    "  wait N                         render N frames\n"
    "  quit\n";

namespace {

struct Pick {
  Eigen::Vector3d p;
};

struct AppState {
  PackReader pack;
  std::unique_ptr<Renderer> renderer = std::make_unique<Renderer>();  // reset before the context goes
  CameraController cc;
  RenderSettings rs;
  Eigen::Vector3d lo, hi, pivot;
  std::vector<Pick> picks;
  std::vector<std::string> results;  // measurement log lines (CSV)
  std::deque<float> frameMs;
  FrameStats stats;
  bool showHelp = false, useColorChoice = true;
  int shadingChoice = 0;
  float clipBox[6] = {0, 0, 0, 1, 1, 1};  // fractions of the bounds
  bool clipBoxOn = false, sectionOn = false;
  int sectionAxis = 0;
  float sectionAt = 0.5f;
  std::string status;
  std::string packPath;
  std::string pendingWindowShot;
  bool streamErrorShown = false;  // a tile that failed to decode was reported
  std::FILE* measureOut = stdout;
  GrooveSet grooves;   // --grooves
  int grooveSel = -1;  // selected in the panel or by the script
};

void logResult(AppState& s, const std::string& line) {
  s.results.push_back(line);
  std::fprintf(s.measureOut, "%s\n", line.c_str());
  std::fflush(s.measureOut);
}

bool pickAt(AppState& s, double px, double py, Eigen::Vector3d& out) {
  const float d = s.renderer->depthAt(int(px), int(py));
  if (!std::isfinite(d)) return false;
  // The renderer's depth is for the pixel centre: unproject that exact ray.
  out = s.cc.unproject(std::floor(px) + 0.5, std::floor(py) + 0.5, d);
  return true;
}

void addPick(AppState& s, double px, double py) {
  Eigen::Vector3d p;
  if (!pickAt(s, px, py, p)) {
    s.status = "nothing under the cursor";
    logResult(s, "pick,miss," + std::to_string(px) + "," + std::to_string(py));
    return;
  }
  s.picks.push_back({p});
  char buf[256];
  std::snprintf(buf, sizeof(buf), "pick,%zu,%.6f,%.6f,%.6f", s.picks.size() - 1, p.x(), p.y(), p.z());
  logResult(s, buf);
  s.status = buf;
}

void measure(AppState& s, const std::string& what) {
  char buf[256];
  if (what == "distance" || what == "height") {
    if (s.picks.size() < 2) {
      s.status = "pick two points first";
      return;
    }
    const Eigen::Vector3d a = s.picks[s.picks.size() - 2].p, b = s.picks.back().p;
    const double v = what == "distance" ? (b - a).norm() : (b - a).dot(s.rs.up.normalized());
    std::snprintf(buf, sizeof(buf), "%s,%zu,%zu,%.9g", what.c_str(), s.picks.size() - 2, s.picks.size() - 1, v);
  } else {
    double len = 0;
    for (size_t i = 1; i < s.picks.size(); ++i) len += (s.picks[i].p - s.picks[i - 1].p).norm();
    std::snprintf(buf, sizeof(buf), "polyline,%zu,%.9g", s.picks.size(), len);
  }
  logResult(s, buf);
  s.status = buf;
}

void applyClip(AppState& s) {
  s.rs.clip.box = s.clipBoxOn;
  const Eigen::Vector3d ext = s.hi - s.lo;
  for (int a = 0; a < 3; ++a) {
    s.rs.clip.lo[a] = s.lo[a] + ext[a] * std::min(s.clipBox[a], s.clipBox[a + 3]);
    s.rs.clip.hi[a] = s.lo[a] + ext[a] * std::max(s.clipBox[a], s.clipBox[a + 3]);
  }
  s.rs.clip.plane = s.sectionOn;
  s.rs.clip.normal = Eigen::Vector3d::Zero();
  s.rs.clip.normal[s.sectionAxis] = -1;
  s.rs.clip.point = s.lo + ext * 0.5;
  s.rs.clip.point[s.sectionAxis] = s.lo[s.sectionAxis] + ext[s.sectionAxis] * s.sectionAt;
}

Status screenshot(AppState& s, const std::string& path, int width = 0, int height = 0) {
  FrameResult fr;
  Camera cam = s.cc.camera();
  if (width > 0 && height > 0) {
    cam.width = width;
    cam.height = height;
  }
  SA_RETURN_IF_ERROR(s.renderer->render(cam, s.rs, fr, kReadColor));
  SA_RETURN_IF_ERROR(writeImage(path, fr.color));
  s.status = "saved " + path;
  return Status::ok();
}

Status bookmark(AppState& s) {
  const std::string path = s.packPath + ".views.json";
  std::vector<Camera> cams;
  if (std::filesystem::exists(path)) {
    auto old = readCameraPath(path, s.cc.camera().width, s.cc.camera().height);
    if (old) cams = *old;
  }
  cams.push_back(s.cc.camera());
  SA_RETURN_IF_ERROR(writeCameraPath(path, cams));
  s.status = "bookmark " + std::to_string(cams.size()) + " saved to " + path;
  return Status::ok();
}

// Runs one (parsed, checked) script command; sets `quit` on quit.
// The point halfway along a polyline.
Eigen::Vector3d midpoint(const std::vector<Eigen::Vector3d>& l) {
  double total = 0;
  for (size_t k = 0; k + 1 < l.size(); ++k) total += (l[k + 1] - l[k]).norm();
  double run = 0;
  for (size_t k = 0; k + 1 < l.size(); ++k) {
    const double seg = (l[k + 1] - l[k]).norm();
    if (run + seg >= total / 2 && seg > 0) return l[k] + (l[k + 1] - l[k]) * ((total / 2 - run) / seg);
    run += seg;
  }
  return l.empty() ? Eigen::Vector3d::Zero() : l[0];
}

// Selects groove i and flies there: the view direction kept, the whole groove (at least 20
// widths of it) in view; its measures go to the log.
void flyToGroove(AppState& s, int i) {
  const Groove& g = s.grooves.grooves[size_t(i)];
  s.grooveSel = i;
  Camera& cam = s.cc.camera();
  const Eigen::Vector3d c = midpoint(g.line), f = cam.forward();
  const double extent = std::max({g.length, 20 * g.width, 1e-9});
  const double dist = 0.6 * extent / std::tan(cam.fovDeg * M_PI / 360);
  cam.target = c;
  cam.eye = c - f * dist;
  s.pivot = c;
  char line[320];
  std::snprintf(line, sizeof(line), "groove,%d,%s,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g", i, g.shape.c_str(), g.width,
                g.shape == "gap" ? NAN : g.depth, g.length, c.x(), c.y(), c.z());
  logResult(s, line);
}

// The grooves over the view: each polyline projected (drawn over the surface, not hidden by
// it), the selected one thicker in yellow.
void drawGrooveOverlay(AppState& s) {
  if (s.grooves.grooves.empty()) return;
  ImDrawList* dl = ImGui::GetBackgroundDrawList();
  const double toWindow = 1.0 / std::max(ImGui::GetIO().DisplayFramebufferScale.x, 1e-3f);
  std::vector<ImVec2> pts;
  for (size_t i = 0; i < s.grooves.grooves.size(); ++i) {
    const Groove& g = s.grooves.grooves[i];
    pts.clear();
    for (const Eigen::Vector3d& p : g.line) {
      double px, py;
      if (!s.cc.project(p, px, py)) {
        pts.clear();
        break;
      }
      pts.push_back(ImVec2(float(px * toWindow), float(py * toWindow)));
    }
    if (pts.size() < 2) continue;
    const bool sel = int(i) == s.grooveSel;
    const ImU32 col = sel ? IM_COL32(255, 230, 0, 255) : g.shape == "gap" ? IM_COL32(60, 120, 255, 200) : IM_COL32(255, 60, 0, 200);
    dl->AddPolyline(pts.data(), int(pts.size()), col, 0, sel ? 3.f : 1.5f);
  }
}

// The groove list: click a row to fly there.
void drawGroovePanel(AppState& s) {
  const auto& gs = s.grooves.grooves;
  if (gs.empty() || !ImGui::CollapsingHeader("Grooves")) return;
  ImGui::Text("%zu grooves (widths +- %.3g: the sample spacing)", gs.size(), s.grooves.spacing);
  if (ImGui::BeginListBox("##grooves", ImVec2(-1, 160))) {
    for (size_t i = 0; i < gs.size(); ++i) {
      char row[160];
      if (gs[i].shape == "gap")
        std::snprintf(row, sizeof(row), "%3zu %-3s w %.3g  d ?  len %.3g", i, gs[i].shape.c_str(), gs[i].width, gs[i].length);
      else
        std::snprintf(row, sizeof(row), "%3zu %-3s w %.3g  d %.3g  len %.3g", i, gs[i].shape.c_str(), gs[i].width,
                      gs[i].depth, gs[i].length);
      if (ImGui::Selectable(row, int(i) == s.grooveSel)) flyToGroove(s, int(i));
    }
    ImGui::EndListBox();
  }
}

Status runCommand(AppState& s, GLFWwindow* win, const ScriptCommand& c, bool& quit, int& waitFrames) {
  const std::string& cmd = c.name;
  const std::vector<double>& v = c.numbers;
  const std::vector<std::string>& words = c.words;
  Camera& cam = s.cc.camera();
  if (cmd == "quit") {
    quit = true;
  } else if (cmd == "size") {
    glfwSetWindowSize(win, int(v[0]), int(v[1]));
    waitFrames = 2;
  } else if (cmd == "camera") {
    cam.eye = Eigen::Vector3d(v[0], v[1], v[2]);
    cam.target = Eigen::Vector3d(v[3], v[4], v[5]);
    if (v.size() >= 9) cam.up = Eigen::Vector3d(v[6], v[7], v[8]);
    if (v.size() >= 10) cam.fovDeg = v[9];
    s.pivot = cam.target;
    SA_RETURN_IF_ERROR(cam.validate());
  } else if (cmd == "orbit") {
    s.cc.orbit(s.pivot, v[0], v[1]);
  } else if (cmd == "pan") {
    s.cc.pan(v[0], v[1], (s.pivot - cam.eye).dot(cam.forward()));
  } else if (cmd == "zoom") {
    const float d = s.renderer->depthAt(int(v[0]), int(v[1]));
    s.cc.zoomToCursor(v[0], v[1], std::isfinite(d) ? double(d) : (s.pivot - cam.eye).dot(cam.forward()), v[2]);
  } else if (cmd == "frame") {
    s.cc.frameAll(s.lo, s.hi);
  } else if (cmd == "top" || cmd == "front" || cmd == "side") {
    s.cc.preset(cmd == "top" ? CameraController::Preset::kTop
                : cmd == "front" ? CameraController::Preset::kFront : CameraController::Preset::kSide, s.lo, s.hi);
  } else if (cmd == "pick") {
    addPick(s, v[0], v[1]);
  } else if (cmd == "distance" || cmd == "polyline" || cmd == "height") {
    measure(s, cmd);
  } else if (cmd == "clear") {
    s.picks.clear();
  } else if (cmd == "clip") {
    if (words[0] == "off") {
      s.rs.clip = ClipSettings{};
    } else if (words[0] == "box") {
      s.rs.clip.box = true;
      s.rs.clip.lo = Eigen::Vector3d(v[0], v[1], v[2]).cwiseMin(Eigen::Vector3d(v[3], v[4], v[5]));
      s.rs.clip.hi = Eigen::Vector3d(v[0], v[1], v[2]).cwiseMax(Eigen::Vector3d(v[3], v[4], v[5]));
    } else {
      s.rs.clip.plane = true;
      s.rs.clip.point = Eigen::Vector3d(v[0], v[1], v[2]);
      s.rs.clip.normal = Eigen::Vector3d(v[3], v[4], v[5]);
    }
  } else if (cmd == "shading") {
    const std::string m = words[0];
    s.rs.useColor = m == "color";
    s.rs.shading = m == "normals" ? Shading::kNormals : m == "height" ? Shading::kHeight : Shading::kLambert;
    s.shadingChoice = m == "color" ? 3 : int(s.rs.shading);
  } else if (cmd == "edl") {
    s.rs.edl = words[0] == "on";
  } else if (cmd == "boxes") {
    s.rs.showBoxes = words[0] == "on";
  } else if (cmd == "iterations") {
    s.rs.iterations = std::max(1, int(v[0]));
  } else if (cmd == "screenshot") {
    SA_RETURN_IF_ERROR(screenshot(s, words[0], v.size() >= 2 ? int(v[0]) : 0, v.size() >= 2 ? int(v[1]) : 0));
    waitFrames = 1;  // the next frame renders at window size again
  } else if (cmd == "windowshot") {
    s.pendingWindowShot = words[0];
  } else if (cmd == "bookmark") {
    SA_RETURN_IF_ERROR(bookmark(s));
  } else if (cmd == "wait") {
    waitFrames = int(v[0]);
  } else if (cmd == "groove") {
    if (v[0] < 0 || v[0] >= double(s.grooves.grooves.size()))
      return Status::badInput("groove " + std::to_string(int(v[0])) + ": --grooves holds " +
                              std::to_string(s.grooves.grooves.size()) + " grooves");
    flyToGroove(s, int(v[0]));
  }
  return Status::ok();
}

// The slices count (0: auto, from each cell's distance) and axis; auto mode's switch size; how
// gdm draws its height-field cells; the grooves mode's anti-aliasing.
void drawLodSettings(AppState& s) {
  if (s.rs.mode == RenderMode::kSlices) {
    ImGui::SliderInt("slices (0 auto)", &s.rs.slices, 0, kAutoSlices);
    const char* axes[] = {"nearest the view", "u", "v", "w"};
    int axis = s.rs.sliceAxis + 1;
    if (ImGui::Combo("slice axis", &axis, axes, 4)) s.rs.sliceAxis = axis - 1;
  }
  if (s.rs.mode == RenderMode::kAuto) {
    float px = float(s.rs.autoPixels);
    if (ImGui::SliderFloat("slices under (px)", &px, 1.f, 64.f, "%.0f")) s.rs.autoPixels = px;
    ImGui::Text("%u boxes as slices, %u marched, %u splats", s.stats.sliced, s.stats.drawn, s.stats.splats);
  }
  if (s.rs.mode == RenderMode::kGdm)
    ImGui::Checkbox("height-field cells by parallax (else exact)", &s.rs.gdmParallaxElsewhere);
  if (s.rs.mode == RenderMode::kGrooves) {
    ImGui::Checkbox("anti-alias grooves under 2 px", &s.rs.grooveAA);
    if (s.rs.grooveAA) ImGui::SliderInt("rays inside a narrow groove", &s.rs.grooveSamples, 2, 32);
  }
}

// The panel's surface section: the mode menu (every mode of the registry, what a pack without its
// section draws instead), the work counters, the march settings and the skips.
void drawSurfacePanel(AppState& s) {
  if (ImGui::CollapsingHeader("Surface", ImGuiTreeNodeFlags_DefaultOpen)) {
    // Every mode of the registry; one the pack has not baked draws its fallback (said below).
    const auto modes = allModes();
    int mode = 0;
    for (size_t i = 0; i < modes.size(); ++i)
      if (modes[i].mode == s.rs.mode) mode = int(i);
    std::vector<const char*> names;
    for (const ModeInfo& m : modes) names.push_back(m.name);
    if (ImGui::Combo("mode", &mode, names.data(), int(names.size()))) {
      RenderMode want = modes[size_t(mode)].mode;
      if (want == RenderMode::kPoints && !s.renderer->hasPoints()) {
        Status ls = uploadSourcePoints(s.pack, *s.renderer);
        if (!ls) {
          s.status = ls.message();
          want = RenderMode::kParallax;
        }
      }
      s.rs.mode = want;
    }
    if (s.rs.mode != RenderMode::kPoints && s.renderer->drawnMode(s.rs.mode) != s.rs.mode)
      ImGui::TextWrapped("not baked into this pack: drawing %s (scanatlas bake PACK --mode %s)",
                         modeName(s.renderer->drawnMode(s.rs.mode)), modeName(s.rs.mode));
    drawLodSettings(s);
    ImGui::Checkbox("work counters", &s.rs.countWork);
    if (s.rs.countWork && s.stats.work.valid) {
      const WorkCounters& w = s.stats.work;
      ImGui::Text("%s/ray mean %.1f p50 %u p99 %u max %u", s.stats.drawnMode == RenderMode::kParallax ? "samples" : "nodes",
                  w.mean(), w.p50, w.p99, w.max);
      if (w.lookups)
        ImGui::Text("%s lookups %llu: %.1f%% fell back, %.1f%% fast misses", modeName(s.rs.mode), (unsigned long long)w.lookups,
                    100.0 * double(w.fallbacks) / double(w.lookups), 100.0 * double(w.fastMisses) / double(w.lookups));
    }
    ImGui::SliderInt("iterations", &s.rs.iterations, 1, 64);
    ImGui::Checkbox("frustum cull", &s.rs.cull.frustum);
    ImGui::SameLine();
    ImGui::Checkbox("adaptive steps", &s.rs.cull.adaptiveSteps);
    ImGui::Checkbox("back-face cull", &s.rs.cull.backfaceCull);
    ImGui::SameLine();
    ImGui::Checkbox("splats", &s.rs.cull.subpixelSplats);
    ImGui::Checkbox("cell boxes (coloured by plane orientation)", &s.rs.showBoxes);
  }
}

void drawShadingPanel(AppState& s) {
  if (!ImGui::CollapsingHeader("Shading", ImGuiTreeNodeFlags_DefaultOpen)) return;
  const char* modes[] = {"Lambert, head light", "normals", "height ramp", "scan colour"};
  if (ImGui::Combo("shading", &s.shadingChoice, modes, 4)) {
    s.rs.useColor = s.shadingChoice == 3;
    s.rs.shading = s.shadingChoice == 1 ? Shading::kNormals : s.shadingChoice == 2 ? Shading::kHeight : Shading::kLambert;
  }
  ImGui::Checkbox("head light", &s.rs.headLight);
  if (!s.rs.headLight) {
    ImGui::Checkbox("self-shadows (second cast toward the light)", &s.rs.shadows);
    static float az = 30.f, el = 45.f;
    ImGui::SliderFloat("light azimuth", &az, -180.f, 180.f);
    ImGui::SliderFloat("light elevation", &el, -89.f, 89.f);
    const Eigen::Vector3d up = s.rs.up.normalized();
    const Eigen::Vector3d a = (std::abs(up.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitZ()).cross(up).normalized();
    const Eigen::Vector3d b = up.cross(a);
    const double ra = az * M_PI / 180, re = el * M_PI / 180;
    s.rs.lightDir = std::cos(re) * (std::cos(ra) * b + std::sin(ra) * a) + std::sin(re) * up;
  }
  ImGui::Checkbox("eye-dome lighting", &s.rs.edl);
  if (s.rs.edl) ImGui::SliderFloat("EDL strength", &s.rs.edlStrength, 0.1f, 5.f);
  ImGui::ColorEdit3("background", s.rs.background);
}

void drawClipPanel(AppState& s) {
  if (!ImGui::CollapsingHeader("Clip")) return;
  bool changed = ImGui::Checkbox("clip box", &s.clipBoxOn);
  changed |= ImGui::SliderFloat3("min", s.clipBox, 0.f, 1.f);
  changed |= ImGui::SliderFloat3("max", s.clipBox + 3, 0.f, 1.f);
  changed |= ImGui::Checkbox("section plane", &s.sectionOn);
  const char* axes[] = {"x", "y", "z"};
  changed |= ImGui::Combo("axis", &s.sectionAxis, axes, 3);
  changed |= ImGui::SliderFloat("at", &s.sectionAt, 0.f, 1.f);
  if (changed) applyClip(s);
}

void drawMeasurePanel(AppState& s) {
  if (!ImGui::CollapsingHeader("Measure", ImGuiTreeNodeFlags_DefaultOpen)) return;
  ImGui::TextWrapped("P: pick under the cursor. Double-click: set the orbit pivot.");
  for (size_t i = 0; i < s.picks.size(); ++i) ImGui::Text("%zu: %.4f %.4f %.4f", i, s.picks[i].p.x(), s.picks[i].p.y(), s.picks[i].p.z());
  if (ImGui::Button("distance")) measure(s, "distance");
  ImGui::SameLine();
  if (ImGui::Button("polyline")) measure(s, "polyline");
  ImGui::SameLine();
  if (ImGui::Button("height")) measure(s, "height");
  ImGui::SameLine();
  if (ImGui::Button("clear")) s.picks.clear();
  if (ImGui::Button("export CSV")) {
    const std::string path = s.packPath + ".measurements.csv";
    std::string text;
    for (const auto& r : s.results) text += r + "\n";
    Status st = writeFileAtomic(path, text.data(), text.size());
    s.status = st ? "wrote " + path : st.message();
  }
}

void drawViewsPanel(AppState& s) {
  if (!ImGui::CollapsingHeader("Views")) return;
  if (ImGui::Button("bookmark view (B)")) {
    Status st = bookmark(s);
    if (!st) s.status = st.message();
  }
  ImGui::SameLine();
  if (ImGui::Button("screenshot (F12)")) {
    Status st = screenshot(s, s.packPath + ".screenshot.png");
    if (!st) s.status = st.message();
  }
  const std::string views = s.packPath + ".views.json";
  if (std::filesystem::exists(views)) {
    auto cams = readCameraPath(views, s.cc.camera().width, s.cc.camera().height);
    for (size_t i = 0; cams && i < cams->size(); ++i) {
      if (i % 6) ImGui::SameLine();
      if (ImGui::Button(("view " + std::to_string(i + 1)).c_str())) {
        s.cc.camera() = (*cams)[i];
        s.pivot = (*cams)[i].target;
      }
    }
  }
  static bool vsync = true;
  if (ImGui::Checkbox("vsync", &vsync)) glfwSwapInterval(vsync ? 1 : 0);
}

void drawKeysWindow(AppState& s) {
  if (!s.showHelp) return;
  ImGui::SetNextWindowPos(ImVec2(360, 10), ImGuiCond_FirstUseEver);
  ImGui::Begin("Keys (H)", &s.showHelp);
  ImGui::TextUnformatted(
      "left drag      orbit about the pivot\n"
      "middle / shift-drag   pan\n"
      "wheel          zoom toward the cursor\n"
      "double-click   set the pivot on the surface\n"
      "W A S D Q E    fly (shift: faster)\n"
      "F              frame all\n"
      "1 / 3 / 7      front / side / top view\n"
      "P              pick a point (measure)\n"
      "B              bookmark the view\n"
      "F12            screenshot\n"
      "H              this help\n"
      "Esc            clear picks");
  ImGui::End();
}

void drawPanel(AppState& s) {
  ImGui::SetNextWindowPos(ImVec2(10, 10), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowSize(ImVec2(330, 560), ImGuiCond_FirstUseEver);
  ImGui::Begin("ScanAtlas");
  std::vector<float> ft(s.frameMs.begin(), s.frameMs.end());
  const float last = ft.empty() ? 0.f : ft.back();
  ImGui::Text("%.1f ms  %.1f fps", last, last > 0 ? 1000.f / last : 0.f);
  if (!ft.empty()) ImGui::PlotLines("##ft", ft.data(), int(ft.size()), 0, "frame ms", 0.f, 100.f, ImVec2(300, 50));
  ImGui::Text("boxes %u drawn, %u culled, %u splats", s.stats.drawn, s.stats.culled, s.stats.splats);
  ImGui::Text("atlas %.1f MiB on the GPU", s.renderer->gpuBytes() / 1048576.0);
  drawSurfacePanel(s);
  drawGroovePanel(s);
  drawShadingPanel(s);
  drawClipPanel(s);
  drawMeasurePanel(s);
  drawViewsPanel(s);
  if (!s.status.empty()) ImGui::TextWrapped("%s", s.status.c_str());
  ImGui::End();
  drawKeysWindow(s);
}


// The pack, its grooves (--grooves, else the pack's own), the script (read and checked whole before
// the window opens) and the measurements file. An error names the file; nothing is opened.
Status loadViewerInputs(AppState& s, const std::string& packPath, const ViewerOptions& opt, std::vector<ScriptCommand>& script) {
  s.packPath = packPath;
  // Tiles decoded as the window needs them; under --gpu-budget into the cache only (no page memory).
  Status st = s.pack.open(packPath, opt.gpuBudget.bytes ? PageLoad::kTiles : PageLoad::kOnDemand);
  if (!st) return Status::badInput(st.message() + "\n(run 'scanatlas info' on it, or repack)");
  std::vector<std::string> inputs = packSources(s.pack);  // the points mode reads them
  inputs.insert(inputs.end(), {packPath, opt.scriptPath, opt.groovesPath});
  if (!opt.groovesPath.empty()) {
    Result<GrooveSet> g = readGroovesJson(opt.groovesPath);
    if (!g) return g.status();
    s.grooves = std::move(*g);
  } else {
    // A pack baked with grooves lists them, and draws them carved (--mode grooves) from the start.
    Result<GrooveSet> g = grooves::packGrooves(s.pack);
    if (!g) return g.status();
    if (!g->grooves.empty()) s.rs.mode = RenderMode::kGrooves;
    s.grooves = std::move(*g);
  }
  if (!opt.scriptPath.empty()) {
    auto loaded = loadScript(opt.scriptPath, inputs);
    if (!loaded) return loaded.status();
    script = std::move(*loaded);
  }
  if (!opt.measurementsPath.empty()) {
    SA_RETURN_IF_ERROR(checkNotAnInput(opt.measurementsPath, inputs, "--measurements"));
    s.measureOut = std::fopen(opt.measurementsPath.c_str(), "w");
    if (!s.measureOut) return Status::badInput(opt.measurementsPath + ": cannot write measurements");
  }
  return Status::ok();
}

// A GL 4.5 core window with Dear ImGui on it; nullptr (and a message) when there is no display.
GLFWwindow* openWindow(const ViewerOptions& opt, const std::string& title, bool vsync) {
  if (!glfwInit()) {
    std::fprintf(stderr, "scanatlas: error: cannot open a window (no display?). Headless: scanatlas render\n");
    return nullptr;
  }
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 5);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_SCALE_TO_MONITOR, GLFW_TRUE);
  GLFWwindow* win = glfwCreateWindow(opt.width, opt.height, title.c_str(), nullptr, nullptr);
  if (!win) {
    const char* desc = nullptr;
    glfwGetError(&desc);
    std::fprintf(stderr, "scanatlas: error: cannot create an OpenGL 4.5 core window: %s\n", desc ? desc : "unknown");
    glfwTerminate();
    return nullptr;
  }
  glfwMakeContextCurrent(win);
  glfwSwapInterval(vsync ? 1 : 0);
  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGui::GetIO().IniFilename = nullptr;
  ImGui_ImplGlfw_InitForOpenGL(win, true);
  ImGui_ImplOpenGL3_Init("#version 450");
  return win;
}

void closeWindow(AppState& s, GLFWwindow* win) {
  ImGui_ImplOpenGL3_Shutdown();
  ImGui_ImplGlfw_Shutdown();
  ImGui::DestroyContext();
  s.renderer.reset();  // GL objects go while the context is current
  glfwDestroyWindow(win);
  glfwTerminate();
}

// Mouse: left drag orbits about the pivot (a double click sets it), middle or shift-left pans
// at the depth under the cursor, the wheel zooms toward the cursor.
struct MouseState {
  double lastX = 0, lastY = 0, lastClick = -1;
  bool dragging = false, panning = false;
  double dragDepth = 1;
};

void handleMouse(AppState& s, GLFWwindow* win, MouseState& ms, double mx, double my) {
  ImGuiIO& io = ImGui::GetIO();
  const Camera& cam = s.cc.camera();
  if (!io.WantCaptureMouse) {
    const bool left = glfwGetMouseButton(win, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS;
    const bool middle = glfwGetMouseButton(win, GLFW_MOUSE_BUTTON_MIDDLE) == GLFW_PRESS;
    const bool shift = glfwGetKey(win, GLFW_KEY_LEFT_SHIFT) == GLFW_PRESS;
    if ((left || middle) && !ms.dragging && !ms.panning) {
      ms.panning = middle || shift;
      ms.dragging = !ms.panning;
      const float d = s.renderer->depthAt(int(mx), int(my));
      ms.dragDepth = std::isfinite(d) ? double(d) : (s.pivot - cam.eye).dot(cam.forward());
      if (left && !shift) {
        const double t = glfwGetTime();
        if (t - ms.lastClick < 0.3) {
          Eigen::Vector3d p;
          if (pickAt(s, mx, my, p)) {
            s.pivot = p;
            s.status = "pivot set";
          }
        }
        ms.lastClick = t;
      }
    } else if (ms.dragging && left) {
      s.cc.orbit(s.pivot, mx - ms.lastX, my - ms.lastY);
    } else if (ms.panning && (left || middle)) {
      s.cc.pan(mx - ms.lastX, my - ms.lastY, ms.dragDepth);
    }
    if (!left && !middle) ms.dragging = ms.panning = false;
    if (io.MouseWheel != 0) {
      const float d = s.renderer->depthAt(int(mx), int(my));
      const double depth = std::isfinite(d) ? double(d) : (s.pivot - cam.eye).dot(cam.forward());
      s.cc.zoomToCursor(mx, my, depth, std::pow(0.85, io.MouseWheel));
    }
  }
  ms.lastX = mx;
  ms.lastY = my;
}

// Keys: WASD/QE fly (shift: 4x), F frames all, 1/3/7 presets, P picks, B bookmarks, F12 saves a
// screenshot, H the help, Esc clears the picks.
void handleKeys(AppState& s, GLFWwindow* win, double dt, double diag, double mx, double my) {
  if (ImGui::GetIO().WantCaptureKeyboard) return;
  const double speed = diag * 0.3 * dt * (glfwGetKey(win, GLFW_KEY_LEFT_SHIFT) == GLFW_PRESS ? 4 : 1);
  auto key = [&](int k) { return glfwGetKey(win, k) == GLFW_PRESS; };
  s.cc.fly(speed * (key(GLFW_KEY_W) - key(GLFW_KEY_S)), speed * (key(GLFW_KEY_D) - key(GLFW_KEY_A)),
           speed * (key(GLFW_KEY_E) - key(GLFW_KEY_Q)));
  if (ImGui::IsKeyPressed(ImGui::GetKeyIndex(ImGuiKey_Escape))) s.picks.clear();
  if (ImGui::IsKeyPressed(GLFW_KEY_F)) s.cc.frameAll(s.lo, s.hi);
  if (ImGui::IsKeyPressed(GLFW_KEY_H)) s.showHelp = !s.showHelp;
  if (ImGui::IsKeyPressed(GLFW_KEY_1) || ImGui::IsKeyPressed(GLFW_KEY_KP_1)) s.cc.preset(CameraController::Preset::kFront, s.lo, s.hi);
  if (ImGui::IsKeyPressed(GLFW_KEY_3) || ImGui::IsKeyPressed(GLFW_KEY_KP_3)) s.cc.preset(CameraController::Preset::kSide, s.lo, s.hi);
  if (ImGui::IsKeyPressed(GLFW_KEY_7) || ImGui::IsKeyPressed(GLFW_KEY_KP_7)) s.cc.preset(CameraController::Preset::kTop, s.lo, s.hi);
  if (ImGui::IsKeyPressed(GLFW_KEY_P)) addPick(s, mx, my);
  if (ImGui::IsKeyPressed(GLFW_KEY_B)) {
    Status b = bookmark(s);
    if (!b) s.status = b.message();
  }
  if (ImGui::IsKeyPressed(GLFW_KEY_F12)) {
    Status b = screenshot(s, s.packPath + ".screenshot.png");
    if (!b) s.status = b.message();
  }
}

// The window's back buffer as asked by the script's `window-screenshot` (panel included).
void saveWindowShot(AppState& s, int fbw, int fbh) {
  Image img;
  img.width = fbw;
  img.height = fbh;
  img.rgba.resize(size_t(fbw) * fbh * 4);
  std::vector<uint8_t> rows(img.rgba.size());
  glReadBuffer(GL_BACK);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, fbw, fbh, GL_RGBA, GL_UNSIGNED_BYTE, rows.data());
  for (int y = 0; y < fbh; ++y)
    std::memcpy(&img.rgba[size_t(y) * fbw * 4], &rows[size_t(fbh - 1 - y) * fbw * 4], size_t(fbw) * 4);
  for (size_t i = 3; i < img.rgba.size(); i += 4) img.rgba[i] = 255;
  Status ws = writeImage(s.pendingWindowShot, img);
  s.status = ws ? "saved " + s.pendingWindowShot : ws.message();
  s.pendingWindowShot.clear();
}

// The script: one command per frame, after the frame it acts on has been drawn; its end ends the
// session. false: a command failed (reported; rc 2).
struct ScriptRun {
  const std::vector<ScriptCommand>& commands;
  size_t line = 0;
  int waitFrames = 0;
};

bool scriptStep(AppState& s, GLFWwindow* win, ScriptRun& run, const std::string& path, bool& quit) {
  if (s.renderer->tilesPending()) return true;  // a script sees the whole pack: its shots do not depend on timing
  if (run.waitFrames > 0) {
    --run.waitFrames;
  } else if (run.line < run.commands.size()) {
    const ScriptCommand& command = run.commands[run.line++];
    Status cs = runCommand(s, win, command, quit, run.waitFrames);
    if (!cs) {
      std::fprintf(stderr, "scanatlas: error: %s:%zu: %s\n", path.c_str(), command.line, cs.message().c_str());
      quit = true;
      return false;
    }
  } else if (!run.commands.empty()) {
    quit = true;
  }
  return true;
}

void reportFirstFrame(AppState& s, std::chrono::steady_clock::time_point tOpen) {
  std::fprintf(stderr, "view: first frame %.0f ms after opening the pack (%s, %u cells, %.1f MiB on the GPU)\n",
               std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - tOpen).count(),
               reinterpret_cast<const char*>(glGetString(GL_RENDERER)), s.pack.meta().cellCount, s.renderer->gpuBytes() / 1048576.0);
}

// A tile that failed to decode while streaming: said once, on stderr and in the panel.
void reportStreamError(AppState& s) {
  if (s.streamErrorShown) return;
  const std::string e = s.renderer->streamError();
  if (e.empty()) return;
  std::fprintf(stderr, "scanatlas: error: %s (that cell is not drawn)\n", e.c_str());
  s.status = e;
  s.streamErrorShown = true;
}

// The first frame that lacked no visible cell's tile (streamed packs decode and upload the
// nearest visible cells first).
void reportViewComplete(AppState& s, std::chrono::steady_clock::time_point tOpen) {
  std::fprintf(stderr, "view: every visible cell drawn %.0f ms after opening the pack (%u of %u tiles resident)\n",
               std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - tOpen).count(),
               s.renderer->tilesResident(), s.pack.meta().cellCount);
}

void reportMedianFrame(const AppState& s, int fbw, int fbh) {
  std::vector<float> ft(s.frameMs.begin(), s.frameMs.end());
  std::sort(ft.begin(), ft.end());
  std::fprintf(stderr, "view: median frame %.1f ms over the last %zu frames (%dx%d)\n", ft[ft.size() / 2], ft.size(), fbw, fbh);
}

// The camera's start: the whole pack framed from the first orbit view.
void initView(AppState& s, GLFWwindow* win) {
  const PackMeta& m = s.pack.meta();
  const Eigen::Vector3d origin(m.origin);
  s.lo = origin + Eigen::Vector3d(m.boundsMin);
  s.hi = origin + Eigen::Vector3d(m.boundsMax);
  int fbw, fbh;
  glfwGetFramebufferSize(win, &fbw, &fbh);
  s.rs.up = s.pack.viewUp();
  s.cc = CameraController(orbitCameras(s.lo, s.hi, 1, s.rs.up, 40, std::max(fbw, 1), std::max(fbh, 1))[0]);
  s.pivot = s.cc.camera().target;
}

}  // namespace

int runViewer(const std::string& packPath, const ViewerOptions& opt) {
  const auto tOpen = std::chrono::steady_clock::now();
  AppState s;
  std::vector<ScriptCommand> script;
  Status st = loadViewerInputs(s, packPath, opt, script);
  if (!st) {
    std::fprintf(stderr, "scanatlas: error: %s\n", st.message().c_str());
    return 2;
  }
  const std::string title = "ScanAtlas — " + std::filesystem::path(packPath).filename().string();
  GLFWwindow* win = openWindow(opt, title, opt.vsync && script.empty());
  if (!win) return 1;
  int rc = 0;
  GpuBudget budget = opt.gpuBudget;
  boundByGpuMemory(budget, "view", opt.quiet);
  st = s.renderer->init(s.pack, /*streamPages=*/true, budget.bytes);
  if (!st) {
    std::fprintf(stderr, "scanatlas: error: %s\n", st.message().c_str());
    rc = 1;
  }
  initView(s, win);
  int fbw = 0, fbh = 0;
  ScriptRun run{script};
  MouseState mouse;
  bool quit = rc != 0, firstFrame = true, viewComplete = false;
  auto lastTime = std::chrono::steady_clock::now();
  const double diag = (s.hi - s.lo).norm();
  while (!quit && !glfwWindowShouldClose(win)) {
    glfwPollEvents();
    glfwGetFramebufferSize(win, &fbw, &fbh);
    if (fbw <= 0 || fbh <= 0) continue;
    int ww, wh;
    glfwGetWindowSize(win, &ww, &wh);
    const double scale = ww > 0 ? double(fbw) / ww : 1.0;  // high-DPI: cursor in window units
    s.cc.setViewport(fbw, fbh);
    const auto now = std::chrono::steady_clock::now();
    const double dt = std::chrono::duration<double>(now - lastTime).count();
    lastTime = now;
    ImGui_ImplOpenGL3_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
    double mx, my;
    glfwGetCursorPos(win, &mx, &my);
    mx *= scale;
    my *= scale;
    handleMouse(s, win, mouse, mx, my);
    handleKeys(s, win, dt, diag, mx, my);
    // The scene.
    FrameResult fr;
    Status rst = s.renderer->render(s.cc.camera(), s.rs, fr, 0u);
    if (!rst) {
      std::fprintf(stderr, "scanatlas: error: %s\n", rst.message().c_str());
      rc = 1;
      break;
    }
    s.stats = fr.stats;
    s.frameMs.push_back(float(fr.stats.cpuMs));
    if (s.frameMs.size() > 120) s.frameMs.pop_front();
    if (!scriptStep(s, win, run, opt.scriptPath, quit)) rc = 2;
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glViewport(0, 0, fbw, fbh);
    s.renderer->present(fbw, fbh);
    drawGrooveOverlay(s);
    drawPanel(s);
    ImGui::Render();
    ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
    if (!s.pendingWindowShot.empty()) saveWindowShot(s, fbw, fbh);
    char t[256];
    char loading[64] = "";
    if (s.renderer->tilesPending())
      std::snprintf(loading, sizeof loading, " (loading tiles: %u of %u)", s.renderer->tilesResident(), s.pack.meta().cellCount);
    std::snprintf(t, sizeof(t), "%s — %.1f ms%s", title.c_str(), fr.stats.cpuMs, loading);
    glfwSetWindowTitle(win, t);
    glfwSwapBuffers(win);
    if (firstFrame && !opt.quiet) reportFirstFrame(s, tOpen);
    if (!viewComplete && fr.stats.missing == 0 && !opt.quiet) reportViewComplete(s, tOpen);
    viewComplete = viewComplete || fr.stats.missing == 0;
    firstFrame = false;
    reportStreamError(s);
  }
  if (!opt.quiet && !s.frameMs.empty()) reportMedianFrame(s, fbw, fbh);
  closeWindow(s, win);
  if (s.measureOut != stdout) std::fclose(s.measureOut);
  return rc;
}

}  // namespace sa
