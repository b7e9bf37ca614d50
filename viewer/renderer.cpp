#include "viewer/renderer.h"

#include "modes/exact/exact.h"
#include "modes/gdm/gdm.h"
#include "modes/grooves/groove_cast.h"
#include "modes/vdm/vdm.h"
#include "viewer/tile_cache.h"
#include "viewer/tile_streamer.h"

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

namespace sa {
namespace {

#ifndef GL_FRAGMENT_SHADER_INVOCATIONS_ARB
#define GL_FRAGMENT_SHADER_INVOCATIONS_ARB 0x82F4
#endif

// Expands `#include "name"` lines with the embedded files (`#include <mode>` with the mode's cast
// unit, modeUnit) and inserts `defines` after the #version line.
// Expands `#include "name"` lines (recursively) with the embedded text.
std::string expandIncludes(const std::string& text, const std::string& modeUnit, int depth) {
  std::istringstream in(text);
  std::string line, out;
  while (std::getline(in, line)) {
    std::string inc;
    if (line.rfind("#include <mode>", 0) == 0) inc = modeUnit;
    else if (line.rfind("#include \"", 0) == 0) inc = line.substr(10, line.find('"', 10) - 10);
    if (inc.empty()) {
      out += line + "\n";
      continue;
    }
    const char* body = embeddedShader(inc);
    out += body && depth < 8 ? expandIncludes(body, modeUnit, depth + 1) : "#error missing include " + inc + "\n";
  }
  return out;
}

// The shader `name` with its includes expanded (`#include <mode>`: the mode's cast unit,
// modeUnit) and `defines` inserted after the #version line.
std::string shaderSource(const std::string& name, const std::string& defines, const std::string& modeUnit) {
  const char* text = embeddedShader(name);
  if (!text) return {};
  const std::string all = expandIncludes(text, modeUnit, 0);
  const size_t eol = all.find('\n');
  return eol == std::string::npos ? all : all.substr(0, eol + 1) + defines + all.substr(eol + 1);
}

Status compile(GLenum type, const std::string& name, const std::string& defines, const std::string& modeUnit,
               GLuint& shader) {
  const std::string src = shaderSource(name, defines, modeUnit);
  if (src.empty()) return Status::internal("shader " + name + " is not embedded");
  shader = glCreateShader(type);
  const char* p = src.c_str();
  glShaderSource(shader, 1, &p, nullptr);
  glCompileShader(shader);
  GLint ok = 0;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[4096];
    glGetShaderInfoLog(shader, sizeof(log), nullptr, log);
    return Status::internal("shader " + name + " failed to compile:\n" + log);
  }
  return Status::ok();
}

Status link(const std::string& vs, const std::string& fs, const std::string& defines, GLuint& program,
            const std::string& modeUnit = "parallax_cast.glsl") {
  GLuint v = 0, f = 0;
  SA_RETURN_IF_ERROR(compile(GL_VERTEX_SHADER, vs, defines, modeUnit, v));
  SA_RETURN_IF_ERROR(compile(GL_FRAGMENT_SHADER, fs, defines, modeUnit, f));
  program = glCreateProgram();
  glAttachShader(program, v);
  glAttachShader(program, f);
  glLinkProgram(program);
  glDeleteShader(v);
  glDeleteShader(f);
  GLint ok = 0;
  glGetProgramiv(program, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[4096];
    glGetProgramInfoLog(program, sizeof(log), nullptr, log);
    return Status::internal("shader program " + vs + " + " + fs + " failed to link:\n" + log);
  }
  return Status::ok();
}

struct GpuCell {
  float originHi[4], originLo[4], u[4], v[4], w[4], boxUV[4], boxW[4];
  int32_t tile[4];
};
static_assert(sizeof(GpuCell) == 128);

void splitDouble(double d, float& hi, float& lo) {
  hi = static_cast<float>(d);
  lo = static_cast<float>(d - static_cast<double>(hi));
}

size_t alignUp(size_t v, GLint a) { return (v + size_t(a) - 1) / size_t(a) * size_t(a); }

bool hasExtension(const char* name) {
  GLint n = 0;
  glGetIntegerv(GL_NUM_EXTENSIONS, &n);
  for (GLint i = 0; i < n; ++i)
    if (!std::strcmp(reinterpret_cast<const char*>(glGetStringi(GL_EXTENSIONS, GLuint(i))), name)) return true;
  return false;
}

}  // namespace


struct Renderer::Gl {
  // Per surface mode (indexed by RenderMode): programs for boxes the camera is outside of
  // (front faces) and inside of (back faces); 0 where the mode cannot draw this pack.
  GLuint front[kRenderModes] = {}, inside[kRenderModes] = {};
  // The same with self-shadowing (SHADOWS: llvmpipe runs a shadow ray's code on every pixel, asked
  // for or not), linked when a frame first asks for shadows.
  GLuint shadowFront[kRenderModes] = {}, shadowInside[kRenderModes] = {};
  // grooves' second pass over the pixels the first deferred (grooves_defer.glsl), packed densely:
  // class 0 (the carved cast), class 1 (the march's hit stands, the footprint's anti-aliasing),
  // class 0 with self-shadowing (linked when first asked for); the depth buffer from the linear
  // depth after it (for the decomposition view's box edges).
  GLuint groovePixel[3] = {}, grooveDepth = 0;
  GLuint splat = 0, points = 0, edl = 0, boxes = 0;  // programs
  GLuint vao = 0, pointVao = 0, cellBuf = 0, itemBuf = 0, pointBuf = 0;
  GLuint mipBuf = 0, mipOffBuf = 0, counterBuf = 0;  // exact: maxima, per-cell offsets; work counters
  GLuint vdmEntryBuf = 0, vdmWordBuf = 0;            // vdm: per-cell block offsets, the blocks
  GLuint gdmEntryBuf = 0, gdmWordBuf = 0;            // gdm: per-cell block offsets, the voxel grids
  GLuint grooveEntryBuf = 0, grooveWordBuf = 0;      // grooves: per-cell block offsets, profiles and blocks
  GLuint grooveFieldBuf = 0;                         // grooves: the cells' gap fields (gcast::gapField)
  GLuint grooveTex[3] = {};  // grooves: the field, the block offsets and the words as buffer textures (units 8-10)
  GLuint cellTex = 0;        // grooves' second pass: the cell table as a buffer texture (unit 11)
  // grooves' deferred pixels at the framebuffer's size (grooves_defer.glsl): slots a pixel, the
  // lists of pixels and their indirect draws; the pack target the cast runs a list's pixels on
  // (no attachments: it writes the frame's targets as images).
  GLuint deferSlotsTex = 0, deferBuf = 0;
  uint32_t packCapacity = 0;  // pixels a slot's two lists hold
  GLuint packFbo = 0;
  int packW = 0, packH = 0;
  GLsizeiptr itemCapacity = 0;
  GLuint heightTex = 0, pageColorTex = 0, normalTex = 0;  // heights: R16UI, --gpu-budget RG16UI (with the masks)
  std::vector<uint16_t> heightMask;  // --gpu-budget: a level's heights and masks interleaved for upload
  // Streamed packs: the decoder, the cells decoded and waiting for upload, residency per cell.
  const PackReader* pack = nullptr;
  std::unique_ptr<TileStreamer> streamer;
  std::vector<uint32_t> uploadQueue;
  std::vector<uint8_t> resident;
  uint32_t residentCount = 0;
  bool visibleOnly = false;  // Streaming::kVisible: no streamer, loadVisibleTiles decodes
  uint32_t lastMissing = 0;  // the visible cells the last frame lacked
  std::string streamError;
  // --gpu-budget: the tile cache's residency; per cell, its levels in memory (built by the
  // decoder from the level asked for, wantLevel, down; the finer ones dropped once a level is
  // uploaded), the finest of them (availFrom), whether it is being decoded, when it was last
  // visible; the cells holding levels and their bytes; the last frame's plan.
  std::unique_ptr<TileResidency> residency;
  std::vector<std::vector<TileImage>> levels;
  std::vector<uint8_t> availFrom, inFlight;
  std::vector<std::atomic<uint8_t>> wantLevel;  // read by the decoding threads
  std::vector<uint64_t> seenAt;
  uint64_t budgetFrame = 0;
  std::vector<uint32_t> held;
  uint64_t heldBytes = 0;
  TileResidency::Frame lastPlan;
  bool budgetSettled = false;
  void releaseTargets() {
    GLuint fbos[] = {fbo, postFbo};
    glDeleteFramebuffers(2, fbos);
    GLuint tex[] = {colorTex, linearTex, frameNormalTex, frameCellTex, postTex, deferSlotsTex};
    glDeleteTextures(6, tex);
    glDeleteBuffers(1, &deferBuf);
    glDeleteFramebuffers(1, &packFbo);
    deferSlotsTex = deferBuf = packFbo = 0;
    glDeleteRenderbuffers(1, &depthRb);
    fbo = postFbo = colorTex = linearTex = frameNormalTex = frameCellTex = postTex = depthRb = 0;
  }
  // The frame's targets: colour, linear depth, normals, cell ids (textures: grooves' second pass
  // writes them as images), the depth buffer.
  GLuint fbo = 0, colorTex = 0, linearTex = 0, frameNormalTex = 0, frameCellTex = 0, depthRb = 0;
  GLuint postFbo = 0, postTex = 0;
  bool lastWasPost = false;
  GLuint timeQuery = 0, fragQuery = 0;
  GLenum fragTarget = GL_SAMPLES_PASSED;
  GLint ssboAlign = 256;  // GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT
  int fbW = 0, fbH = 0;
  ~Gl() {
    streamer.reset();  // its threads write levels and read the pack: join them before anything goes
    for (GLuint p : {splat, points, edl, boxes, groovePixel[0], groovePixel[1], groovePixel[2], grooveDepth})
      if (p) glDeleteProgram(p);
    for (int m = 0; m < kRenderModes; ++m)
      for (GLuint p : {front[m], inside[m], shadowFront[m], shadowInside[m]})
        if (p) glDeleteProgram(p);
    GLuint modeBufs[] = {mipBuf,     mipOffBuf,   counterBuf,     vdmEntryBuf,   vdmWordBuf,
                         gdmEntryBuf, gdmWordBuf, grooveEntryBuf, grooveWordBuf, grooveFieldBuf};
    glDeleteBuffers(10, modeBufs);
    glDeleteTextures(3, grooveTex);
    glDeleteTextures(1, &cellTex);
    GLuint vaos[] = {vao, pointVao};
    glDeleteVertexArrays(2, vaos);
    GLuint bufs[] = {cellBuf, itemBuf, pointBuf};
    glDeleteBuffers(3, bufs);
    releaseTargets();
    GLuint tex[] = {heightTex, pageColorTex, normalTex};
    glDeleteTextures(3, tex);
    GLuint q[] = {timeQuery, fragQuery};
    glDeleteQueries(2, q);
  }
};

Renderer::Renderer() = default;
Renderer::~Renderer() = default;

double Renderer::nearPlane() const { return std::max((boundsMax_ - boundsMin_).norm() / 2, 1e-12) * 1e-5; }

bool Renderer::tilesPending() const {
  if (!gl_) return false;
  if (gl_->residency) return !gl_->budgetSettled;
  if (gl_->visibleOnly) return gl_->lastMissing > 0;
  return gl_->streamer != nullptr;
}

uint32_t Renderer::tilesResident() const {
  if (!gl_) return 0;
  if (gl_->residency) {
    uint32_t n = 0;
    for (uint32_t i = 0; i < cellCount_; ++i) n += gl_->residency->residentFlags()[i];
    return n;
  }
  return gl_->streamer || gl_->visibleOnly ? gl_->residentCount : cellCount_;
}

std::string Renderer::streamError() const {
  if (gl_ && gl_->streamer && gl_->streamError.empty()) {
    Status s = gl_->streamer->error();
    if (!s) gl_->streamError = s.message();
  }
  return gl_ ? gl_->streamError : std::string();
}

Status Renderer::init(const PackReader& pack, bool streamPages, uint64_t gpuBudget, Streaming streaming) {
  gl_ = std::make_unique<Gl>();
  Gl& g = *gl_;
  const PackMeta& m = pack.meta();
  origin_ = Eigen::Vector3d(m.origin[0], m.origin[1], m.origin[2]);
  boundsMin_ = Eigen::Vector3d(m.boundsMin[0], m.boundsMin[1], m.boundsMin[2]);
  boundsMax_ = Eigen::Vector3d(m.boundsMax[0], m.boundsMax[1], m.boundsMax[2]);
  cellCount_ = m.cellCount;
  hasColor_ = pack.hasColor();
  hasNormals_ = pack.hasNormals();
  spacing_ = m.sampleSpacing;
  culler_ = std::make_unique<CellCuller>(pack.cells());
  coverMasks_ = gpuBudget != 0;
  SA_RETURN_IF_ERROR(initModes(pack));
  SA_RETURN_IF_ERROR(link("splat.vert", "splat.frag", "", g.splat));
  SA_RETURN_IF_ERROR(link("points.vert", "points.frag", "", g.points));
  SA_RETURN_IF_ERROR(link("fullscreen.vert", "edl.frag", "", g.edl));
  SA_RETURN_IF_ERROR(link("boxes.vert", "boxes.frag", "", g.boxes));
  glCreateVertexArrays(1, &g.vao);
  // glGenQueries, not glCreateQueries: Mesa rejects the pipeline-statistics target there.
  glGenQueries(1, &g.timeQuery);
  glGenQueries(1, &g.fragQuery);
  g.fragTarget = hasExtension("GL_ARB_pipeline_statistics_query") ? GL_FRAGMENT_SHADER_INVOCATIONS_ARB : GL_SAMPLES_PASSED;

  std::vector<GpuCell> cells(m.cellCount);
  auto src = pack.cells();
  for (uint32_t i = 0; i < m.cellCount; ++i) {
    const CellRecord& c = src[i];
    GpuCell& gc = cells[i];
    std::memset(&gc, 0, sizeof(gc));
    for (int a = 0; a < 3; ++a) {
      splitDouble(c.origin[a], gc.originHi[a], gc.originLo[a]);
      gc.u[a] = float(c.u[a]);
      gc.v[a] = float(c.v[a]);
      gc.w[a] = float(c.w[a]);
    }
    for (int a = 0; a < 4; ++a) gc.boxUV[a] = float(c.box[a]);
    gc.boxW[0] = float(c.box[4]);
    gc.boxW[1] = float(c.box[5]);
    gc.boxW[2] = float(c.tileW);
    gc.boxW[3] = float(c.tileH);
    gc.tile[0] = int32_t(c.page);
    gc.tile[1] = int32_t(c.tileX);
    gc.tile[2] = int32_t(c.tileY);
    gc.tile[3] = c.flags;
  }
  glCreateBuffers(1, &g.cellBuf);
  glNamedBufferStorage(g.cellBuf, GLsizeiptr(std::max<size_t>(1, cells.size()) * sizeof(GpuCell)),
                       cells.empty() ? nullptr : cells.data(), gpuBudget ? GL_DYNAMIC_STORAGE_BIT : 0);
  gpuBytes_ = cells.size() * sizeof(GpuCell);
  if (g.grooveEntryBuf) {  // grooves' second pass reads a deferred pixel's cell from it (grooves_defer.glsl)
    glCreateTextures(GL_TEXTURE_BUFFER, 1, &g.cellTex);
    glTextureBuffer(g.cellTex, GL_RGBA32F, g.cellBuf);
  }
  glCreateBuffers(1, &g.itemBuf);
  glGetIntegerv(GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT, &g.ssboAlign);
  g.ssboAlign = std::max(g.ssboAlign, 1);

  GLint maxLayers = 0, maxSize = 0;
  glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &maxLayers);
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &maxSize);
  if (gpuBudget) return initBudget(pack, gpuBudget, maxLayers);
  const GLsizei PW = GLsizei(m.pageWidth), PH = GLsizei(m.pageHeight), PC = GLsizei(m.pageCount);
  if (PC > maxLayers || PW > maxSize || PH > maxSize)
    return Status::internal(pack.path() + ": atlas needs " + std::to_string(m.pageCount) + " layers of " +
                            std::to_string(m.pageWidth) + "x" + std::to_string(m.pageHeight) + " but the GL allows " +
                            std::to_string(maxLayers) + " layers of " + std::to_string(maxSize) + "^2");
  const uint64_t pageTexels = pack.pageTexels() * m.pageCount;
  // An array texture per page channel; a channel the pack lacks gets one constant texel.
  const uint8_t white[4] = {255, 255, 255, 255}, up[2] = {128, 128};  // a lone texel: unsampled without pages
  g.heightTex = pageTexture(GL_R16UI, true, nullptr, 0, PW, PH, PC);
  g.pageColorTex = pageTexture(GL_RGBA8, hasColor_, white, GL_RGBA, PW, PH, PC);
  g.normalTex = pageTexture(kNormalBytes == 2 ? GL_RG8 : GL_RG16, hasNormals_, up, GL_RG, PW, PH, PC);
  gpuBytes_ += pageTexels * (2 + (hasColor_ ? 4 : 0) + (hasNormals_ ? kNormalBytes : 0));
  if (glGetError() != GL_NO_ERROR) return Status::internal("OpenGL error while uploading the pack (out of memory?)");
  if (streamPages) {
    g.pack = &pack;
    g.resident.assign(m.cellCount, 0);
    g.residentCount = 0;
    g.visibleOnly = streaming == Streaming::kVisible;
    if (!g.visibleOnly) g.streamer = std::make_unique<TileStreamer>(pack);  // kVisible: loadVisibleTiles decodes
    return Status::ok();
  }
  if (pack.onDemand()) return Status::internal(pack.path() + ": pages opened on demand must be streamed");
  uploadPages(pack);
  if (glGetError() != GL_NO_ERROR) return Status::internal("OpenGL error while uploading the pack (out of memory?)");
  return Status::ok();
}

// An array texture per page channel of w x h x layers; a channel the pack lacks gets one
// constant texel.
unsigned Renderer::pageTexture(unsigned format, bool present, const uint8_t* fill, unsigned fillFormat, uint32_t w,
                               uint32_t h, uint32_t layers) {
  GLuint t = 0;
  glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &t);
  if (present) {
    glTextureStorage3D(t, 1, format, GLsizei(w), GLsizei(h), GLsizei(layers));
  } else {
    glTextureStorage3D(t, 1, format, 1, 1, 1);
    glTextureSubImage3D(t, 0, 0, 0, 0, 1, 1, 1, fillFormat, GL_UNSIGNED_BYTE, fill);
  }
  glTextureParameteri(t, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTextureParameteri(t, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  return t;
}

// --gpu-budget: the page textures are a cache of square layers (the largest tile with its gutter,
// at least 256 texels, to a power of two) as many as the budget holds; tiles stream in as the
// frames plan, at the level each cell's projected texel size asks for. A height texel holds the
// texel's coverage mask beside it (TileImage::cover; level 0 all set): one fetch reads both.
Status Renderer::initBudget(const PackReader& pack, uint64_t budget, int maxLayers) {
  Gl& g = *gl_;
  uint32_t size = 256;
  for (const CellRecord& c : pack.cells())
    while (size < uint32_t(std::max(c.tileW, c.tileH)) + 2) size <<= 1;
  const uint64_t texelBytes = 2 + (hasColor_ ? 4 : 0) + (hasNormals_ ? kNormalBytes : 0) + 2;  // + the mask
  const uint64_t layerBytes = uint64_t(size) * size * texelBytes;
  const uint64_t layers = std::max<uint64_t>(1, budget / layerBytes);
  if (layers > uint64_t(maxLayers))
    return Status::badInput("--gpu-budget " + std::to_string(budget >> 20) + " MiB needs " + std::to_string(layers) +
                            " texture layers of " + std::to_string(size) + "^2 but the GL allows " + std::to_string(maxLayers));
  const uint8_t white[4] = {255, 255, 255, 255}, up[2] = {128, 128};
  g.heightTex = pageTexture(GL_RG16UI, true, nullptr, 0, size, size, uint32_t(layers));
  g.pageColorTex = pageTexture(GL_RGBA8, hasColor_, white, GL_RGBA, size, size, uint32_t(layers));
  g.normalTex = pageTexture(kNormalBytes == 2 ? GL_RG8 : GL_RG16, hasNormals_, up, GL_RG, size, size, uint32_t(layers));
  gpuBytes_ += layers * layerBytes;
  if (glGetError() != GL_NO_ERROR) return Status::internal("OpenGL error while allocating the tile cache (out of memory?)");
  for (const ModeInfo& mi : allModes())
    if (!budgetMode(mi.mode)) modeProblems_[int(mi.mode)] = "--gpu-budget: this mode needs every tile at full resolution";
  g.pack = &pack;
  g.residency = std::make_unique<TileResidency>(pack.cells(), size, uint32_t(layers), texelBytes);
  g.levels.resize(cellCount_);
  g.availFrom.assign(cellCount_, TileResidency::kNoLevel);
  g.inFlight.assign(cellCount_, 0);
  g.wantLevel = std::vector<std::atomic<uint8_t>>(cellCount_);
  g.seenAt.assign(cellCount_, 0);
  // Only the cells asked for, from the level asked for down: what is held in memory follows the
  // view, not the pack's size. A tile that fails to decode gets uncovered levels (the cell never
  // draws) and the error is reported once.
  g.streamer = std::make_unique<TileStreamer>(
      pack, 0,
      [&g, &pack](uint32_t i) { return buildLevels(pack, i, g.wantLevel[i].load(), g.levels[i]); },
      TileStreamer::Order::kOnRequest);
  return Status::ok();
}

// --gpu-budget: one tile level into its cache block (the image with its gutter at the block's
// corner), and the cell's entry pointed at it.
void Renderer::uploadLevel(const TileResidency::Upload& u) {
  Gl& g = *gl_;
  const PackReader& pack = *g.pack;
  const CellRecord& c = pack.cells()[u.cell];
  uint32_t w, h;
  TileResidency::levelSize(c, u.level, w, h);
  const GLint x = GLint(u.block.x), y = GLint(u.block.y), z = GLint(u.block.layer);
  const GLsizei W = GLsizei(w + 2), H = GLsizei(h + 2);
  const GLenum nType = kNormalBytes == 2 ? GL_UNSIGNED_BYTE : GL_UNSIGNED_SHORT;
  const TileImage& t = g.levels[u.cell][u.level];
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);  // rows of an odd number of 2-byte texels
  g.heightMask.resize(t.heights.size() * 2);
  for (size_t k = 0; k < t.heights.size(); ++k) {
    g.heightMask[2 * k] = t.heights[k];
    g.heightMask[2 * k + 1] = t.cover.empty() ? kFullCover : t.cover[k];
  }
  glTextureSubImage3D(g.heightTex, 0, x, y, z, W, H, 1, GL_RG_INTEGER, GL_UNSIGNED_SHORT, g.heightMask.data());
  if (hasColor_) glTextureSubImage3D(g.pageColorTex, 0, x, y, z, W, H, 1, GL_RGBA, GL_UNSIGNED_BYTE, t.rgba.data());
  if (hasNormals_) glTextureSubImage3D(g.normalTex, 0, x, y, z, W, H, 1, GL_RG, nType, t.normals.data());
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  const float size[2] = {float(w), float(h)};
  const int32_t tile[3] = {int32_t(u.block.layer), int32_t(u.block.x + 1), int32_t(u.block.y + 1)};
  const GLintptr base = GLintptr(u.cell) * GLintptr(sizeof(GpuCell));
  glNamedBufferSubData(g.cellBuf, base + GLintptr(offsetof(GpuCell, boxW) + 8), sizeof size, size);
  glNamedBufferSubData(g.cellBuf, base + GLintptr(offsetof(GpuCell, tile)), sizeof tile, tile);
}

// --gpu-budget: cell c's levels from `from` on kept, the finer ones dropped (from = kNoLevel:
// all; the streamer may then decode it again).
void Renderer::dropLevels(uint32_t c, uint32_t from) {
  Gl& g = *gl_;
  if (g.availFrom[c] == TileResidency::kNoLevel || from <= g.availFrom[c]) return;
  const uint64_t before = levelBytes(g.levels[c]);
  if (from >= g.levels[c].size()) {
    g.levels[c] = {};
    g.availFrom[c] = TileResidency::kNoLevel;
    g.streamer->release(c);
  } else {
    for (uint32_t l = g.availFrom[c]; l < from; ++l) g.levels[c][l] = TileImage{g.levels[c][l].w, g.levels[c][l].h, {}, {}, {}, {}};
    g.availFrom[c] = uint8_t(from);
  }
  g.heldBytes -= before - levelBytes(g.levels[c]);
}

// --gpu-budget: the cells decoded since join those holding levels.
void Renderer::takeLevels() {
  Gl& g = *gl_;
  for (uint32_t i : g.streamer->takeDecoded()) {
    g.inFlight[i] = 0;
    uint8_t from = TileResidency::kNoLevel;
    for (size_t l = 0; l < g.levels[i].size() && from == TileResidency::kNoLevel; ++l)
      if (!g.levels[i][l].heights.empty()) from = uint8_t(l);
    if (from == TileResidency::kNoLevel) continue;
    g.availFrom[i] = from;
    g.heldBytes += levelBytes(g.levels[i]);
    g.held.push_back(i);
  }
}

// --gpu-budget, after a frame's uploads: memory is kept for the levels planned (on the GPU, or
// waiting for a free block) and the coarser ones only; cells evicted, or neither resident nor visible this frame, let go of theirs.
void Renderer::trimLevels(const TileResidency::Frame& plan) {
  Gl& g = *gl_;
  for (const TileResidency::Upload& u : plan.uploads) dropLevels(u.cell, u.wanted);  // the planned level stays for a later try
  for (uint32_t c : plan.dropped) dropLevels(c, TileResidency::kNoLevel);
  size_t keep = 0;
  for (uint32_t c : g.held) {
    if (g.availFrom[c] != TileResidency::kNoLevel && g.residency->level(c) < 0 && g.seenAt[c] != g.budgetFrame)
      dropLevels(c, TileResidency::kNoLevel);
    if (g.availFrom[c] != TileResidency::kNoLevel) g.held[keep++] = c;
  }
  g.held.resize(keep);
}

// --gpu-budget, each frame before drawing: the cells decoded since, every visible cell's level
// planned against the cache, up to 64 MiB of levels uploaded, the levels the view lacks asked
// for (what the cell holds dropped, finer ones first in the plan's order). Returns whether any
// level was uploaded.
bool Renderer::planBudget(const Camera& cam, const Eigen::Vector3d& camRel, const VisibleSet& vis, FrameStats& st) {
  Gl& g = *gl_;
  takeLevels();
  ++g.budgetFrame;
  std::vector<uint32_t> visible = vis.missing;
  for (const std::vector<DrawItem>* list : {&vis.front, &vis.inside, &vis.splats, &vis.sliced})
    for (const DrawItem& d : *list) visible.push_back(d.cell);
  for (uint32_t c : visible) g.seenAt[c] = g.budgetFrame;
  const double focalPx = cam.height / (2 * std::tan(cam.fovDeg * M_PI / 360.0));
  g.lastPlan = g.residency->plan(visible, g.availFrom.data(), camRel, focalPx, uint64_t(64) << 20);
  for (const TileResidency::Upload& u : g.lastPlan.uploads) uploadLevel(u);
  trimLevels(g.lastPlan);
  // The wish is every need, those already asked for included (the streamer skips what it has
  // begun); a cell arriving coarser than the view now wants is asked for again.
  std::vector<uint32_t> ask;
  for (const TileResidency::Need& n : g.lastPlan.needs) {
    if (!g.inFlight[n.cell]) {
      dropLevels(n.cell, TileResidency::kNoLevel);  // a finer level than it holds: decoded again
      g.wantLevel[n.cell] = uint8_t(n.level);
      g.inFlight[n.cell] = 1;
    }
    ask.push_back(n.cell);
  }
  g.streamer->want(std::move(ask));
  st.uploads = uint32_t(g.lastPlan.uploads.size());
  st.evicted = g.lastPlan.evicted;
  st.coarsened = g.lastPlan.coarsened;
  st.budgetBias = g.lastPlan.bias;
  st.residentBytes = g.residency->residentBytes();
  st.heldBytes = g.heldBytes;
  g.budgetSettled = g.lastPlan.waiting == 0 && g.lastPlan.uploads.empty();
  return !g.lastPlan.uploads.empty();
}

// A mode section's per-cell entry table and its blocks of words (vdm, gdm) as two storage
// buffers; returns their bytes.
static uint64_t uploadBlocks(uint32_t cellCount, const uint32_t* entries, uint64_t wordCount, const uint32_t* words,
                             GLuint& entryBuf, GLuint& wordBuf) {
  glCreateBuffers(1, &entryBuf);
  glNamedBufferStorage(entryBuf, GLsizeiptr(std::max<size_t>(cellCount, 1) * 4), entries, 0);
  glCreateBuffers(1, &wordBuf);
  const uint32_t zero = 0;
  glNamedBufferStorage(wordBuf, GLsizeiptr(std::max<uint64_t>(wordCount, 1) * 4), wordCount ? static_cast<const void*>(words) : &zero, 0);
  return (uint64_t(cellCount) + wordCount) * 4;
}

// grooves' deferred pixels (grooves_defer.glsl): slots a pixel (8 bytes each: 4 leave 42 of 17653
// deferred pixels of Igea's test views to their height field, 3 left 200); the lists' words
// before their pixels (defer_lists.glsl): a draw command and a pixel count a list, then the
// pixels deferred and those without a slot.
constexpr int kDeferSlots = 4;
constexpr int kDeferLists = 2 * kDeferSlots;
constexpr int kDeferCountAt = 4 * kDeferLists + kDeferLists;
constexpr int kDeferHead = kDeferCountAt + 2;
static std::string deferDefines() { return "#define DEFER_SLOTS " + std::to_string(kDeferSlots) + "\n"; }

// A surface mode's box programs: front faces (the camera outside the box) or back faces (inside);
// grooves: the first pass (the height field's march, deferring where the carved cast can differ).
static std::string boxDefines(RenderMode m, bool inside) {
  return std::string(inside ? "" : "#define FRONT_FACES 1\n") + (m == RenderMode::kGrooves ? "#define GROOVES_DEFER 1\n" + deferDefines() : "");
}

// --gpu-budget: the surface programs read the levels' coverage masks (heightfield.glsl); without
// a budget every tile is level 0 and the programs go without them.
std::string Renderer::maskDefines() const { return coverMasks_ ? "#define COVER_MASKS 1\n" : ""; }

// The self-shadowing programs a frame drawing mode m needs (its own, parallax's for the cells it
// leaves to them, grooves' second pass), linked the first time.
Status Renderer::ensureShadowPrograms(RenderMode m) {
  Gl& g = *gl_;
  for (RenderMode k : {m, RenderMode::kParallax}) {
    const ModeInfo& mi = modeInfo(k);
    const int i = int(k);
    if (!mi.castUnit || mi.vertexShader || !g.front[i] || g.shadowFront[i]) continue;
    SA_RETURN_IF_ERROR(link("box.vert", "parallax.frag", boxDefines(k, false) + maskDefines() + "#define SHADOWS 1\n", g.shadowFront[i], mi.castUnit));
    SA_RETURN_IF_ERROR(link("box.vert", "parallax.frag", boxDefines(k, true) + maskDefines() + "#define SHADOWS 1\n", g.shadowInside[i], mi.castUnit));
  }
  if (m == RenderMode::kGrooves && g.groovePixel[0] && !g.groovePixel[2])
    SA_RETURN_IF_ERROR(link("defer_pack.vert", "parallax.frag", "#define PIXEL_RAYS 1\n#define SHADOWS 1\n" + deferDefines(), g.groovePixel[2],
                            modeInfo(m).castUnit));
  return Status::ok();
}

// grooves: the section's blocks, the cells' gap fields (buffer textures: grooves.glsl) and the
// second pass's programs. Not usable (the mode's problem says why) where one of them is longer
// than a buffer texture may be on this GPU.
Status Renderer::initGrooves(const PackReader& pack, const gcast::SectionView& v, bool& usable) {
  Gl& g = *gl_;
  const std::vector<uint32_t> field = gcast::gapField(pack, gcast::modelFromSection(pack, v));
  GLint maxTexels = 0;
  glGetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &maxTexels);
  const uint64_t longest = std::max({uint64_t(v.header.cellCount), uint64_t(v.header.wordCount), uint64_t(field.size()),
                                     uint64_t(pack.meta().cellCount) * (sizeof(GpuCell) / 16)});
  usable = longest <= uint64_t(std::max(maxTexels, 0));
  if (!usable) {
    modeProblems_[int(RenderMode::kGrooves)] = "the grooves section, gap field and cell table need " + std::to_string(longest) +
                                               " words in one buffer texture, more than this GPU's " + std::to_string(maxTexels);
    return Status::ok();
  }
  grooveBytes_ = uploadBlocks(v.header.cellCount, v.entries, v.header.wordCount, v.words, g.grooveEntryBuf, g.grooveWordBuf);
  grooveKind_.assign(v.header.cellCount, 0);
  for (uint32_t i = 0; i < v.header.cellCount; ++i) grooveKind_[i] = v.entries[i] != gcast::kNoEntry ? 1 : 0;
  glCreateBuffers(1, &g.grooveFieldBuf);
  glNamedBufferStorage(g.grooveFieldBuf, GLsizeiptr(std::max<size_t>(field.size(), 1) * 4), field.data(), 0);
  const GLuint bufs[3] = {g.grooveFieldBuf, g.grooveEntryBuf, g.grooveWordBuf};
  for (int i = 0; i < 3; ++i) {
    glCreateTextures(GL_TEXTURE_BUFFER, 1, &g.grooveTex[i]);
    glTextureBuffer(g.grooveTex[i], GL_R32UI, bufs[i]);
  }
  grooveBytes_ += field.size() * 4;
  gpuBytes_ += grooveBytes_;
  const char* unit = modeInfo(RenderMode::kGrooves).castUnit;
  SA_RETURN_IF_ERROR(link("defer_pack.vert", "parallax.frag", "#define PIXEL_RAYS 1\n" + deferDefines(), g.groovePixel[0], unit));
  SA_RETURN_IF_ERROR(link("defer_pack.vert", "parallax.frag", "#define PIXEL_RAYS 1\n#define GROOVES_HIT_STANDS 1\n" + deferDefines(),
                          g.groovePixel[1], unit));
  return link("fullscreen.vert", "depth_from_linear.frag", "", g.grooveDepth);
}

// Every surface mode this pack can draw: its programs and its baked sections on the GPU.
Status Renderer::initModes(const PackReader& pack) {
  Gl& g = *gl_;
  for (const ModeInfo& mi : allModes()) {
    if (mi.vertexShader) {  // draws its own geometry (slices): one program, no box faces
      SA_RETURN_IF_ERROR(link(mi.vertexShader, mi.fragmentShader, maskDefines(), g.front[int(mi.mode)]));
      continue;
    }
    if (!mi.castUnit) continue;
    // A section this build cannot use (an older version, corrupt) leaves its mode to its fallback,
    // with the reason (modeProblem); the other modes draw.
    auto unusable = [&](const Status& s) {
      modeProblems_[int(mi.mode)] = s.message();
      return true;
    };
    if (mi.mode == RenderMode::kExact) {
      auto v = exact::readSection(pack);
      if (!v.isOk() && unusable(v.status())) continue;
      if (!v->present) continue;  // drawn as its fallback (drawnMode)
      if (v->codeCount >= (uint64_t(1) << 32))
        return Status::badInput(pack.path() + ": the exact mode's maxima exceed 2^32 codes; render with --mode parallax");
      std::vector<uint32_t> offsets(pack.cells().size());
      for (size_t i = 0; i < offsets.size(); ++i) offsets[i] = uint32_t(v->offsets[i] / 2);  // a node a word
      const uint64_t words = v->codeCount / 2;
      glCreateBuffers(1, &g.mipBuf);
      glNamedBufferStorage(g.mipBuf, GLsizeiptr(std::max<uint64_t>(words, 1) * 4), nullptr, GL_DYNAMIC_STORAGE_BIT);
      if (v->codeCount) glNamedBufferSubData(g.mipBuf, 0, GLsizeiptr(v->codeCount * 2), v->codes);
      glCreateBuffers(1, &g.mipOffBuf);
      glNamedBufferStorage(g.mipOffBuf, GLsizeiptr(std::max<size_t>(offsets.size(), 1) * 4), offsets.empty() ? nullptr : offsets.data(), 0);
      exactBytes_ = words * 4 + offsets.size() * 4;
      gpuBytes_ += exactBytes_;
    }
    if (mi.mode == RenderMode::kGdm) {
      auto v = gdm::readSection(pack);
      if (!v.isOk() && unusable(v.status())) continue;
      if (!v->present || !g.mipBuf) continue;  // gdm's other cells draw exact
      gdmBytes_ = uploadBlocks(v->header.cellCount, v->entries, v->header.wordCount, v->words, g.gdmEntryBuf, g.gdmWordBuf);
      gpuBytes_ += gdmBytes_;
      gdmKind_.assign(v->header.cellCount, 0);
      for (uint32_t i = 0; i < v->header.cellCount; ++i) gdmKind_[i] = v->entries[i] != gdm::kNoEntry ? 2 : 0;
    }
    if (mi.mode == RenderMode::kGrooves) {
      auto v = gcast::readSection(pack);
      if (!v.isOk() && unusable(v.status())) continue;
      if (!v->present) continue;  // drawn as parallax: a groove neither detected nor given is never drawn
      bool usable = false;
      SA_RETURN_IF_ERROR(initGrooves(pack, *v, usable));
      if (!usable) continue;  // drawn as parallax, with the reason
    }
    if (mi.mode == RenderMode::kVdm) {
      auto v = vdm::readSection(pack);
      if (!v.isOk() && unusable(v.status())) continue;
      if (!v->present || !g.mipBuf) continue;  // vdm needs exact's maxima for its fallback
      vdmBytes_ = uploadBlocks(v->header.cellCount, v->entries, v->header.wordCount, v->words, g.vdmEntryBuf, g.vdmWordBuf);
      gpuBytes_ += vdmBytes_;
    }
    const int k = int(mi.mode);
    SA_RETURN_IF_ERROR(link("box.vert", "parallax.frag", boxDefines(mi.mode, false) + maskDefines(), g.front[k], mi.castUnit));
    SA_RETURN_IF_ERROR(link("box.vert", "parallax.frag", boxDefines(mi.mode, true) + maskDefines(), g.inside[k], mi.castUnit));
  }
  glCreateBuffers(1, &g.counterBuf);
  glNamedBufferStorage(g.counterBuf, (8 + 256) * 4, nullptr, GL_DYNAMIC_STORAGE_BIT | GL_MAP_READ_BIT);
  return Status::ok();
}

bool Renderer::modeReady(RenderMode m) const {
  if (m == RenderMode::kPoints) return hasPoints();
  if (gl_ && gl_->residency && !budgetMode(m)) return false;  // needs every tile at level 0
  return gl_ && gl_->front[int(m)] != 0;
}

RenderMode Renderer::drawnMode(RenderMode m) const {
  // Down the fallback chain (vdm -> exact -> parallax) to the first mode this pack can draw.
  while (m != RenderMode::kPoints && !modeReady(m) && m != RenderMode::kParallax) {
    const char* fb = modeInfo(m).fallback;
    auto next = parseMode(fb ? fb : "parallax");
    m = next.isOk() ? *next : RenderMode::kParallax;
  }
  return m;
}

uint64_t Renderer::modeGpuBytes(RenderMode m) const {
  return m == RenderMode::kExact ? exactBytes_
         : m == RenderMode::kVdm ? vdmBytes_ + exactBytes_
         : m == RenderMode::kGdm ? gdmBytes_ + exactBytes_
         : m == RenderMode::kGrooves ? grooveBytes_
                                 : 0;
}

void WorkCounters::percentiles() {
  auto pct = [&](double q) {
    const uint64_t want = uint64_t(std::ceil(q * double(rays)));
    uint64_t seen = 0;
    for (uint32_t k = 0; k < histogram.size(); ++k)
      if ((seen += histogram[k]) >= want && want > 0) return k;
    return 255u;
  };
  p50 = pct(0.5);
  p90 = pct(0.9);
  p99 = pct(0.99);
}

void WorkCounters::add(const WorkCounters& o) {
  valid = valid || o.valid;
  rays += o.rays;
  work += o.work;
  hits += o.hits;
  capped += o.capped;
  fallbacks += o.fallbacks;
  fastMisses += o.fastMisses;
  lookups += o.lookups;
  max = std::max(max, o.max);
  histogram.resize(256, 0);
  for (size_t k = 0; k < o.histogram.size() && k < 256; ++k) histogram[k] += o.histogram[k];
  percentiles();
}

void Renderer::readCounters(WorkCounters& w) {
  uint32_t c[8 + 256];
  glGetNamedBufferSubData(gl_->counterBuf, 0, sizeof(c), c);
  w.valid = true;
  w.rays = c[0];
  w.work = c[1];
  w.max = c[2];
  w.capped = c[3];
  w.hits = c[4];
  w.fallbacks = c[5];
  w.fastMisses = c[6];
  w.lookups = c[7];
  w.histogram.assign(c + 8, c + 8 + 256);
  w.percentiles();
}

// Every page of a pack whose pages are all in memory (raw, or decoded at open).
void Renderer::uploadPages(const PackReader& pack) {
  Gl& g = *gl_;
  const PackMeta& m = pack.meta();
  const GLsizei PW = GLsizei(m.pageWidth), PH = GLsizei(m.pageHeight);
  for (uint32_t p = 0; p < m.pageCount; ++p) {
    glTextureSubImage3D(g.heightTex, 0, 0, 0, GLint(p), PW, PH, 1, GL_RED_INTEGER, GL_UNSIGNED_SHORT, pack.heightPage(p));
    if (hasColor_)
      glTextureSubImage3D(g.pageColorTex, 0, 0, 0, GLint(p), PW, PH, 1, GL_RGBA, GL_UNSIGNED_BYTE, pack.colorPage(p));
    if (hasNormals_)
      glTextureSubImage3D(g.normalTex, 0, 0, 0, GLint(p), PW, PH, 1, GL_RG, kNormalBytes == 2 ? GL_UNSIGNED_BYTE : GL_UNSIGNED_SHORT,
                          pack.normalPage(p));
  }
}

// Streamed packs: uploads the tiles decoded since the last frame, up to budgetBytes (at least
// one tile), each with its gutter; when every cell is resident, streaming ends.
void Renderer::uploadTiles(uint64_t budgetBytes) {
  Gl& g = *gl_;
  if (g.residency || !(g.streamer || g.visibleOnly)) return;  // --gpu-budget: planBudget uploads
  if (g.streamer) {
    const std::vector<uint32_t> fresh = g.streamer->takeDecoded();
    g.uploadQueue.insert(g.uploadQueue.end(), fresh.begin(), fresh.end());
  }
  const PackReader& pack = *g.pack;
  const uint32_t PW = pack.meta().pageWidth;
  const uint64_t texelBytes = 2 + (hasColor_ ? 4 : 0) + (hasNormals_ ? kNormalBytes : 0);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, GLint(PW));
  uint64_t spent = 0;
  size_t k = 0;
  for (; k < g.uploadQueue.size() && (spent == 0 || spent < budgetBytes); ++k) {
    const uint32_t i = g.uploadQueue[k];
    const CellRecord& c = pack.cells()[i];
    const TileRegion r = gutteredTile(c);
    const uint64_t at = uint64_t(r.y) * PW + r.x;
    const GLint x = GLint(r.x), y = GLint(r.y), z = GLint(c.page);
    const GLsizei w = GLsizei(r.w), h = GLsizei(r.h);
    glTextureSubImage3D(g.heightTex, 0, x, y, z, w, h, 1, GL_RED_INTEGER, GL_UNSIGNED_SHORT, pack.heightPage(c.page) + at);
    if (hasColor_)
      glTextureSubImage3D(g.pageColorTex, 0, x, y, z, w, h, 1, GL_RGBA, GL_UNSIGNED_BYTE, pack.colorPage(c.page) + 4 * at);
    if (hasNormals_)
      glTextureSubImage3D(g.normalTex, 0, x, y, z, w, h, 1, GL_RG, kNormalBytes == 2 ? GL_UNSIGNED_BYTE : GL_UNSIGNED_SHORT,
                          pack.normalPage(c.page) + kNormalBytes * at);
    if (!g.resident[i]) ++g.residentCount;
    g.resident[i] = 1;
    spent += uint64_t(r.w) * r.h * texelBytes;
  }
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
  g.uploadQueue.erase(g.uploadQueue.begin(), g.uploadQueue.begin() + ptrdiff_t(k));
  if (g.streamer && g.residentCount == cellCount_ && g.streamer->done()) {
    streamError();  // keep the decoder's error, if any, past its end
    g.streamer.reset();
    g.pack = nullptr;
    g.resident.clear();
  }
}

void Renderer::waitForTiles() {
  Gl& g = *gl_;
  if (g.visibleOnly) {  // the cells no view has loaded
    std::vector<uint32_t> rest;
    for (uint32_t i = 0; i < cellCount_; ++i)
      if (!g.resident[i]) rest.push_back(i);
    const Status s = g.pack->decodeCells(rest);
    if (!s && g.streamError.empty()) g.streamError = s.message();
    g.uploadQueue.insert(g.uploadQueue.end(), rest.begin(), rest.end());
    uploadTiles(UINT64_MAX);
    return;
  }
  if (!g.streamer) return;
  g.streamer->waitAll();
  uploadTiles(UINT64_MAX);  // --gpu-budget: the frames upload what they plan
}

Status Renderer::loadVisibleTiles(const Camera& cam, const RenderSettings& s) {
  Gl& g = *gl_;
  if (g.streamer && !g.residency) {  // a whole pack streaming: made whole
    waitForTiles();
    const std::string e = streamError();
    return e.empty() ? Status::ok() : Status::badInput(e);
  }
  if (!g.visibleOnly || s.mode == RenderMode::kPoints) return Status::ok();  // points draw no tile
  SA_RETURN_IF_ERROR(cam.validate());
  VisibleSet vis;
  culler_->compute(cam, cam.eye - origin_, nearPlane(), cullOptions(s), vis);
  // In cell order, as a whole pack decodes (the tiles lie in the pages about that way).
  std::sort(vis.missing.begin(), vis.missing.end());
  SA_RETURN_IF_ERROR(g.pack->decodeCells(vis.missing));
  g.uploadQueue.insert(g.uploadQueue.end(), vis.missing.begin(), vis.missing.end());
  uploadTiles(UINT64_MAX);
  return Status::ok();
}

Status Renderer::setPoints(const std::vector<float>& xyz, const std::vector<uint8_t>& rgba, double spacing) {
  Gl& g = *gl_;
  pointCount_ = xyz.size() / 3;
  if (rgba.size() != pointCount_ * 4) return Status::internal("setPoints: colour count does not match");
  spacing_ = spacing > 0 ? spacing : spacing_;
  // Interleaved: 12 bytes position + 4 bytes colour.
  std::vector<uint8_t> inter(pointCount_ * 16);
  for (uint64_t i = 0; i < pointCount_; ++i) {
    std::memcpy(&inter[i * 16], &xyz[3 * i], 12);
    std::memcpy(&inter[i * 16 + 12], &rgba[4 * i], 4);
  }
  if (!g.pointBuf) glCreateBuffers(1, &g.pointBuf);
  glNamedBufferData(g.pointBuf, GLsizeiptr(std::max<size_t>(16, inter.size())), inter.data(), GL_STATIC_DRAW);
  if (!g.pointVao) {
    glCreateVertexArrays(1, &g.pointVao);
    glVertexArrayVertexBuffer(g.pointVao, 0, g.pointBuf, 0, 16);
    glEnableVertexArrayAttrib(g.pointVao, 0);
    glVertexArrayAttribFormat(g.pointVao, 0, 3, GL_FLOAT, GL_FALSE, 0);
    glVertexArrayAttribBinding(g.pointVao, 0, 0);
    glEnableVertexArrayAttrib(g.pointVao, 1);
    glVertexArrayAttribFormat(g.pointVao, 1, 4, GL_UNSIGNED_BYTE, GL_TRUE, 12);
    glVertexArrayAttribBinding(g.pointVao, 1, 0);
  }
  if (glGetError() != GL_NO_ERROR) return Status::internal("OpenGL error while uploading points (out of memory?)");
  return Status::ok();
}

// A render target's texture, read back texel by texel (no filtering).
static GLuint targetTexture(GLenum format, int width, int height) {
  GLuint t = 0;
  glCreateTextures(GL_TEXTURE_2D, 1, &t);
  glTextureStorage2D(t, 1, format, width, height);
  glTextureParameteri(t, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTextureParameteri(t, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTextureParameteri(t, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTextureParameteri(t, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  return t;
}

// grooves' deferred pixels at the frame's size (grooves_defer.glsl): the slots, the lists, and
// the pack target (a list holds each pixel at most once: the frame's pixels, rounded up to 4x4
// blocks), without attachments.
Status Renderer::createDeferTargets(int width, int height) {
  Gl& g = *gl_;
  glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &g.deferSlotsTex);
  glTextureStorage3D(g.deferSlotsTex, 1, GL_R32UI, width, height, 2 * kDeferSlots);
  g.packW = 4 * ((width + 3) / 4);
  g.packH = 4 * ((height + 3) / 4);
  g.packCapacity = uint32_t(g.packW) * uint32_t(g.packH);
  glCreateBuffers(1, &g.deferBuf);
  glNamedBufferStorage(g.deferBuf, GLsizeiptr((kDeferHead + kDeferSlots * uint64_t(g.packCapacity)) * 4), nullptr,
                       GL_DYNAMIC_STORAGE_BIT | GL_MAP_READ_BIT);
  glCreateFramebuffers(1, &g.packFbo);
  glNamedFramebufferParameteri(g.packFbo, GL_FRAMEBUFFER_DEFAULT_WIDTH, g.packW);
  glNamedFramebufferParameteri(g.packFbo, GL_FRAMEBUFFER_DEFAULT_HEIGHT, g.packH);
  if (glCheckNamedFramebufferStatus(g.packFbo, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    return Status::internal("grooves' pack target incomplete at " + std::to_string(g.packW) + "x" + std::to_string(g.packH));
  return Status::ok();
}

// Render targets at the camera's size: colour, linear depth, normals, cell ids, depth buffer,
// and the post-processing target.
Status Renderer::ensureTargets(int width, int height) {
  Gl& g = *gl_;
  if (g.fbW == width && g.fbH == height) return Status::ok();
  g.releaseTargets();
  auto texture = [&](GLenum format) { return targetTexture(format, width, height); };
  g.colorTex = texture(GL_RGBA8);
  g.linearTex = texture(GL_R32F);
  g.postTex = texture(GL_RGBA8);
  g.frameNormalTex = texture(GL_RGBA16F);
  g.frameCellTex = texture(GL_R32UI);
  glCreateRenderbuffers(1, &g.depthRb);
  glNamedRenderbufferStorage(g.depthRb, GL_DEPTH_COMPONENT32F, width, height);
  glCreateFramebuffers(1, &g.fbo);
  glNamedFramebufferTexture(g.fbo, GL_COLOR_ATTACHMENT0, g.colorTex, 0);
  glNamedFramebufferTexture(g.fbo, GL_COLOR_ATTACHMENT1, g.linearTex, 0);
  glNamedFramebufferTexture(g.fbo, GL_COLOR_ATTACHMENT2, g.frameNormalTex, 0);
  glNamedFramebufferTexture(g.fbo, GL_COLOR_ATTACHMENT3, g.frameCellTex, 0);
  glNamedFramebufferRenderbuffer(g.fbo, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, g.depthRb);
  glCreateFramebuffers(1, &g.postFbo);
  glNamedFramebufferTexture(g.postFbo, GL_COLOR_ATTACHMENT0, g.postTex, 0);
  if (g.grooveEntryBuf) SA_RETURN_IF_ERROR(createDeferTargets(width, height));
  if (glCheckNamedFramebufferStatus(g.fbo, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE ||
      glCheckNamedFramebufferStatus(g.postFbo, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    return Status::internal("framebuffer incomplete at " + std::to_string(width) + "x" + std::to_string(height));
  g.fbW = width;
  g.fbH = height;
  return Status::ok();
}

// The culler's options for these settings, with the cells whose tiles are resident.
CullOptions Renderer::cullOptions(const RenderSettings& s) const {
  const Gl& g = *gl_;
  CullOptions co = s.cull;
  co.clipBox = s.clip.box;
  co.clipLo = s.clip.lo - origin_;
  co.clipHi = s.clip.hi - origin_;
  co.clipPlane = s.clip.plane;
  co.planePoint = s.clip.point - origin_;
  co.planeNormal = s.clip.normal.normalized();
  co.maxSteps = std::max(1, s.iterations);
  co.cellResident = g.residency ? g.residency->residentFlags() : !g.resident.empty() ? g.resident.data() : nullptr;
  co.minSteps = std::min(co.minSteps, co.maxSteps);
  co.slicePixels = s.mode == RenderMode::kAuto ? s.autoPixels : 0;
  return co;
}

// Which boxes this frame draws (front faces, inside boxes, splats) and with how many steps,
// uploaded into one buffer: each list starts at an offset the SSBO binding accepts.
void Renderer::uploadVisibility(const Camera& cam, const Eigen::Vector3d& camRel, double np, const RenderSettings& s,
                                VisibleSet& vis, FrameStats& st) {
  Gl& g = *gl_;
  culler_->compute(cam, camRel, np, cullOptions(s), vis);
  st.submitted = vis.submitted;
  st.culled = vis.culled;
  st.drawn = static_cast<uint32_t>(vis.front.size() + vis.inside.size());
  st.inside = static_cast<uint32_t>(vis.inside.size());
  st.splats = static_cast<uint32_t>(vis.splats.size());
  st.sliced = static_cast<uint32_t>(vis.sliced.size());
  st.missing = static_cast<uint32_t>(vis.missing.size());
  // grooves, and gdm with parallax elsewhere: the boxes of the cells the mode's own programs draw
  // apart, by the program that draws them; the others stay for parallax's (llvmpipe pays for a
  // program's size on every pixel it draws).
  for (auto& l : ownLists_) l.clear();
  const RenderMode drawn = drawnMode(s.mode);  // not the mode's own programs where it falls back
  const std::vector<uint8_t>* kind = drawn == RenderMode::kGrooves ? &grooveKind_
                                     : drawn == RenderMode::kGdm && s.gdmParallaxElsewhere ? &gdmKind_
                                                                                            : nullptr;
  if (kind && !kind->empty()) {
    for (int side = 0; side < 2; ++side) {
      std::vector<DrawItem>& list = side ? vis.inside : vis.front;
      size_t keep = 0;
      for (const DrawItem& it : list) {
        const uint8_t k = it.cell < kind->size() ? (*kind)[it.cell] : 0;
        if (k == 0) list[keep++] = it;
        else ownLists_[(k - 1) * 2 + side].push_back(it);
      }
      list.resize(keep);
    }
  }
  const auto order = drawOrder(vis);
  size_t bytes = 0;
  for (const auto* list : order) bytes += alignUp(list->size() * sizeof(DrawItem), g.ssboAlign);
  if (GLsizeiptr(bytes) > g.itemCapacity) {
    g.itemCapacity = GLsizeiptr(std::max<size_t>(bytes, 4096));
    glNamedBufferData(g.itemBuf, g.itemCapacity, nullptr, GL_STREAM_DRAW);
  }
  size_t off = 0;
  for (const auto* list : order) {
    if (!list->empty()) glNamedBufferSubData(g.itemBuf, GLintptr(off), GLsizeiptr(list->size() * sizeof(DrawItem)), list->data());
    off += alignUp(list->size() * sizeof(DrawItem), g.ssboAlign);
  }
}

std::array<const std::vector<DrawItem>*, 8> Renderer::drawOrder(const VisibleSet& vis) const {
  return {&vis.front, &vis.inside, &vis.splats, &vis.sliced, &ownLists_[0], &ownLists_[1], &ownLists_[2], &ownLists_[3]};
}

// Uniforms every surface program reads: camera, projection, shading, clipping.
void Renderer::setCommonUniforms(GLuint p, const FrameUniforms& f, const RenderSettings& s) const {
  glUseProgram(p);
  glUniformMatrix3fv(glGetUniformLocation(p, "viewRotation"), 1, GL_FALSE, f.rot.data());
  glUniformMatrix4fv(glGetUniformLocation(p, "projection"), 1, GL_FALSE, f.proj.data());
  glUniform3fv(glGetUniformLocation(p, "camHi"), 1, f.hi);
  glUniform3fv(glGetUniformLocation(p, "camLo"), 1, f.lo);
  glUniform1i(glGetUniformLocation(p, "refineSteps"), std::max(0, s.refineSteps));
  glUniform1i(glGetUniformLocation(p, "maxSteps"), std::max(1, s.iterations));
  glUniform1f(glGetUniformLocation(p, "nearPlane"), float(f.nearPlane));
  glUniform3fv(glGetUniformLocation(p, "viewForward"), 1, f.fwd.data());
  glUniform1i(glGetUniformLocation(p, "useColor"), s.useColor && hasColor_ ? 1 : 0);
  glUniform1i(glGetUniformLocation(p, "storedNormals"), hasNormals_ ? 1 : 0);
  glUniform3fv(glGetUniformLocation(p, "baseColor"), 1, s.baseColor);
  glUniform1i(glGetUniformLocation(p, "shadingMode"), int(s.shading));
  glUniform1i(glGetUniformLocation(p, "headLight"), s.headLight ? 1 : 0);
  glUniform3fv(glGetUniformLocation(p, "lightDir"), 1, f.light.data());
  glUniform3fv(glGetUniformLocation(p, "upAxis"), 1, f.up.data());
  glUniform1f(glGetUniformLocation(p, "heightLo"), f.heightLo);
  glUniform1f(glGetUniformLocation(p, "heightHi"), f.heightHi);
  glUniform1i(glGetUniformLocation(p, "clipFlags"), (s.clip.box ? 1 : 0) | (s.clip.plane ? 2 : 0));
  glUniform3fv(glGetUniformLocation(p, "clipBoxMin"), 1, f.clipLo.data());
  glUniform3fv(glGetUniformLocation(p, "clipBoxMax"), 1, f.clipHi.data());
  glUniform4fv(glGetUniformLocation(p, "clipPlane"), 1, f.plane.data());
  glUniform1i(glGetUniformLocation(p, "countWork"), s.countWork ? 1 : 0);
  glUniform1i(glGetUniformLocation(p, "shadows"), s.shadows && !s.headLight ? 1 : 0);
  glUniform1ui(glGetUniformLocation(p, "workCap"), 0xfffffffeu);  // a cast that reports more was stopped by its cap
  // grooves: the pixel footprint for anti-aliasing narrow grooves.
  glUniform1f(glGetUniformLocation(p, "pixelAngle"), f.pixelAngle);
  glUniform3fv(glGetUniformLocation(p, "camRight"), 1, f.right.data());
  glUniform3fv(glGetUniformLocation(p, "camUp"), 1, f.camUp.data());
  glUniform1i(glGetUniformLocation(p, "grooveAA"), s.grooveAA ? 1 : 0);
  glUniform1i(glGetUniformLocation(p, "grooveSamples"), std::clamp(s.grooveSamples, 1, 64));
}

// The frame's camera-relative constants (differences formed in double, then float).
Renderer::FrameUniforms Renderer::frameUniforms(const Camera& cam, const RenderSettings& s, const Eigen::Vector3d& camRel,
                                                double np) const {
  FrameUniforms f;
  for (int a = 0; a < 3; ++a) splitDouble(camRel[a], f.hi[a], f.lo[a]);
  f.nearPlane = np;
  f.rot = cam.viewRotation().cast<float>();
  f.proj = cam.projection(np).cast<float>();
  f.fwd = cam.forward().cast<float>();
  f.right = cam.right().cast<float>();
  f.camUp = cam.trueUp().cast<float>();
  // Height ramp range: the bounding box's corners along up.
  const Eigen::Vector3d upD = s.up.normalized();
  f.up = upD.cast<float>();
  double hLo = 1e300, hHi = -1e300;
  for (int k = 0; k < 8; ++k) {
    const Eigen::Vector3d corner(k & 1 ? boundsMax_.x() : boundsMin_.x(), k & 2 ? boundsMax_.y() : boundsMin_.y(),
                                 k & 4 ? boundsMax_.z() : boundsMin_.z());
    const double h = (corner - camRel).dot(upD);
    hLo = std::min(hLo, h);
    hHi = std::max(hHi, h);
  }
  f.heightLo = float(hLo);
  f.heightHi = float(hHi);
  f.pixelAngle = float(cam.fovDeg * M_PI / 180.0 / std::max(cam.height, 1));
  const double ty = std::tan(cam.fovDeg * M_PI / 360.0), tx = ty * cam.width / std::max(cam.height, 1);
  f.rayDx = (cam.right() * (2 * tx / std::max(cam.width, 1))).cast<float>();
  f.rayDy = (cam.trueUp() * (2 * ty / std::max(cam.height, 1))).cast<float>();
  f.rayBase = (cam.forward() - cam.right() * tx - cam.trueUp() * ty).cast<float>();
  f.light = s.lightDir.normalized().cast<float>();
  f.clipLo = (s.clip.lo - cam.eye).cast<float>();
  f.clipHi = (s.clip.hi - cam.eye).cast<float>();
  const Eigen::Vector3d pn = s.clip.normal.normalized();
  f.plane = Eigen::Vector4f(float(pn.x()), float(pn.y()), float(pn.z()), float(-pn.dot(s.clip.point - cam.eye)));
  return f;
}

// The height fields: front faces of boxes the camera is outside of, back faces of those it is
// inside, splats for sub-pixel boxes; then, when asked, the boxes' edges.
void Renderer::drawCells(const VisibleSet& vis, const FrameUniforms& f, const RenderSettings& s, const GLenum* bufs) {
  Gl& g = *gl_;
  glBindVertexArray(g.vao);
  glEnable(GL_CULL_FACE);
  size_t off = 0;
  auto drawList = [&](const std::vector<DrawItem>& list, GLuint program, GLenum cullFace, GLenum prim, GLsizei verts) {
    if (!list.empty()) {
      setCommonUniforms(program, f, s);
      glCullFace(cullFace);
      glBindBufferRange(GL_SHADER_STORAGE_BUFFER, 1, g.itemBuf, GLintptr(off), GLsizeiptr(list.size() * sizeof(DrawItem)));
      glDrawArraysInstanced(prim, 0, verts, GLsizei(list.size()));
    }
    off += alignUp(list.size() * sizeof(DrawItem), g.ssboAlign);
  };
  const int m = int(drawnMode(s.mode));
  const bool shadows = s.shadows && !s.headLight;
  auto front = [&](int k) { return shadows ? g.shadowFront[k] : g.front[k]; };
  auto inside = [&](int k) { return shadows ? g.shadowInside[k] : g.inside[k]; };
  // Slices: every listed cell the same way, whether the camera is inside its box or not;
  // count 0: per cell from its distance, at most autoMax.
  auto drawSlices = [&](const std::vector<DrawItem>& list, int count, int autoMax) {
    const GLuint p = g.front[int(RenderMode::kSlices)];
    glDisable(GL_CULL_FACE);
    const int n = count == 0 ? autoMax : std::clamp(count, 1, kMaxSlices);  // quads an instance draws
    glProgramUniform1i(p, glGetUniformLocation(p, "sliceCount"), count == 0 ? 0 : n);
    glProgramUniform1i(p, glGetUniformLocation(p, "autoSlices"), autoMax);
    glProgramUniform1f(p, glGetUniformLocation(p, "pixelAngle"), f.pixelAngle);
    glProgramUniform1i(p, glGetUniformLocation(p, "sliceAxis"), s.sliceAxis);
    glProgramUniform1i(p, glGetUniformLocation(p, "forcedVoxels"), g.gdmEntryBuf ? 1 : 0);
    drawList(list, p, GL_BACK, GL_TRIANGLES, 6 * (n + 2));  // the slices and two far faces
  };
  if (RenderMode(m) == RenderMode::kSlices) {
    drawSlices(vis.front, s.slices, kAutoSlices);
    drawSlices(vis.inside, s.slices, kAutoSlices);
  } else {
    // (grooves, gdm with parallax elsewhere: these are the cells without grooves or voxels, drawn by
    // parallax's programs; below, the others)
    const bool ownApart = RenderMode(m) == RenderMode::kGrooves || (RenderMode(m) == RenderMode::kGdm && s.gdmParallaxElsewhere);
    const int plain = ownApart ? int(RenderMode::kParallax) : m;
    drawList(vis.front, front(plain), GL_BACK, GL_TRIANGLES, 36);    // camera outside: front faces
    drawList(vis.inside, inside(plain), GL_FRONT, GL_TRIANGLES, 36);  // camera inside: back faces
  }
  glDisable(GL_CULL_FACE);
  drawList(vis.splats, g.splat, GL_BACK, GL_POINTS, 1);
  // auto: the small boxes as slices, enough of them for a pixel along the view.
  int autoMax = 2;
  while (autoMax < kAutoSlices && autoMax < s.autoPixels) autoMax *= 2;
  drawSlices(vis.sliced, 0, autoMax);
  glEnable(GL_CULL_FACE);
  const bool grooves = RenderMode(m) == RenderMode::kGrooves && (!ownLists_[0].empty() || !ownLists_[1].empty());
  if (grooves) beginGrooves(s, front(int(RenderMode::kGrooves)), inside(int(RenderMode::kGrooves)));
  const int gm = RenderMode(m) == RenderMode::kGdm ? int(RenderMode::kGdm) : int(RenderMode::kGrooves);
  drawList(ownLists_[0], front(gm), GL_BACK, GL_TRIANGLES, 36);  // grooves: the first pass
  drawList(ownLists_[1], inside(gm), GL_FRONT, GL_TRIANGLES, 36);
  drawList(ownLists_[2], front(gm), GL_BACK, GL_TRIANGLES, 36);  // gdm's forced cells
  drawList(ownLists_[3], inside(gm), GL_FRONT, GL_TRIANGLES, 36);
  glDisable(GL_CULL_FACE);
  if (grooves) drawDeferredGrooves(f, s, bufs[2] != GL_NONE, bufs[3] != GL_NONE);
  if (!s.showBoxes) return;
  if (grooves) depthFromLinear(f);
  // The decomposition view: every drawn box's edges, depth-tested against the surface.
  off = 0;
  const GLenum only0[] = {GL_COLOR_ATTACHMENT0, GL_NONE, GL_NONE, GL_NONE};
  glNamedFramebufferDrawBuffers(g.fbo, 4, only0);
  glDepthMask(GL_FALSE);
  glDepthFunc(GL_GEQUAL);
  setCommonUniforms(g.boxes, f, s);
  for (const auto* list : drawOrder(vis)) {
    if (!list->empty() && list != &vis.splats && list != &vis.sliced) {
      glBindBufferRange(GL_SHADER_STORAGE_BUFFER, 1, g.itemBuf, GLintptr(off), GLsizeiptr(list->size() * sizeof(DrawItem)));
      glDrawArraysInstanced(GL_LINES, 0, 24, GLsizei(list->size()));
    }
    off += alignUp(list->size() * sizeof(DrawItem), g.ssboAlign);
  }
  glDepthMask(GL_TRUE);
  glDepthFunc(GL_GREATER);
  glNamedFramebufferDrawBuffers(g.fbo, 4, bufs);
}

// grooves' first pass: no pixel deferred yet; the cells' gap fields, the slots and the lists bound.
void Renderer::beginGrooves(const RenderSettings& s, unsigned frontProgram, unsigned insideProgram) {
  Gl& g = *gl_;
  const GLuint zero = 0;
  for (int slot = 0; slot < kDeferSlots; ++slot)  // the cell layers (the hits are written when a slot is taken)
    glClearTexSubImage(g.deferSlotsTex, 0, 0, 0, 2 * slot, g.fbW, g.fbH, 1, GL_RED_INTEGER, GL_UNSIGNED_INT, &zero);
  GLuint head[kDeferHead] = {};  // each list: a point a 4x4 block, none yet; nothing deferred
  for (int l = 0; l < kDeferLists; ++l) head[4 * l] = 1;
  glNamedBufferSubData(g.deferBuf, 0, sizeof(head), head);
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 3, g.deferBuf);
  glBindImageTexture(3, g.deferSlotsTex, 0, GL_TRUE, 0, GL_READ_WRITE, GL_R32UI);
  for (GLuint p : {GLuint(frontProgram), GLuint(insideProgram)}) {
    glProgramUniform1ui(p, glGetUniformLocation(p, "packCapacity"), g.packCapacity);
    glProgramUniform1i(p, glGetUniformLocation(p, "deferAll"), s.shadows && !s.headLight ? 1 : 0);
  }
}

// grooves' second pass: per list, its class's cast over the list's pixels packed into the pack
// target, writing the frame's targets (grooves_defer.glsl deferStore), one list after the other.
void Renderer::drawDeferredGrooves(const FrameUniforms& f, const RenderSettings& s, bool wantNormals, bool wantCells) {
  Gl& g = *gl_;
  glMemoryBarrier(GL_SHADER_IMAGE_ACCESS_BARRIER_BIT | GL_SHADER_STORAGE_BARRIER_BIT | GL_COMMAND_BARRIER_BIT);
  glBindBuffer(GL_DRAW_INDIRECT_BUFFER, g.deferBuf);
  glEnable(GL_PROGRAM_POINT_SIZE);
  glDisable(GL_DEPTH_TEST);
  glBindFramebuffer(GL_FRAMEBUFFER, g.packFbo);
  glViewport(0, 0, g.packW, g.packH);
  glBindImageTexture(4, g.colorTex, 0, GL_FALSE, 0, GL_WRITE_ONLY, GL_RGBA8);
  glBindImageTexture(5, g.linearTex, 0, GL_FALSE, 0, GL_READ_WRITE, GL_R32F);
  glBindImageTexture(6, g.frameNormalTex, 0, GL_FALSE, 0, GL_WRITE_ONLY, GL_RGBA16F);
  glBindImageTexture(7, g.frameCellTex, 0, GL_FALSE, 0, GL_WRITE_ONLY, GL_R32UI);
  for (int cls = 0; cls < 2; ++cls) {
    const GLuint p = cls == 0 && s.shadows && !s.headLight ? g.groovePixel[2] : g.groovePixel[cls];
    setCommonUniforms(p, f, s);
    glUniform1ui(glGetUniformLocation(p, "packCapacity"), g.packCapacity);
    glUniform1ui(glGetUniformLocation(p, "deferClass"), GLuint(cls));
    glUniform1i(glGetUniformLocation(p, "wantNormals"), wantNormals ? 1 : 0);  // else a narrow groove's footprint skips the hit's
    glUniform1i(glGetUniformLocation(p, "wantCells"), wantCells ? 1 : 0);
    glUniform2i(glGetUniformLocation(p, "packSize"), g.packW, g.packH);
    glUniform3fv(glGetUniformLocation(p, "rayBase"), 1, f.rayBase.data());
    glUniform3fv(glGetUniformLocation(p, "rayDx"), 1, f.rayDx.data());
    glUniform3fv(glGetUniformLocation(p, "rayDy"), 1, f.rayDy.data());
    for (int slot = 0; slot < kDeferSlots; ++slot) {
      const int list = 2 * slot + cls;
      glUniform1i(glGetUniformLocation(p, "deferSlot"), slot);
      glUniform1i(glGetUniformLocation(p, "deferList"), list);
      glDrawArraysIndirect(GL_POINTS, reinterpret_cast<const void*>(uintptr_t(list) * 16));
      glMemoryBarrier(GL_SHADER_IMAGE_ACCESS_BARRIER_BIT);  // the next list's depth test reads this one's
    }
  }
  glMemoryBarrier(GL_FRAMEBUFFER_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT | GL_PIXEL_BUFFER_BARRIER_BIT |
                  GL_TEXTURE_UPDATE_BARRIER_BIT);
  glBindFramebuffer(GL_FRAMEBUFFER, g.fbo);
  glViewport(0, 0, g.fbW, g.fbH);
  glEnable(GL_DEPTH_TEST);
  glDisable(GL_PROGRAM_POINT_SIZE);
  glBindBuffer(GL_DRAW_INDIRECT_BUFFER, 0);
}

// The depth buffer from the linear depth, where grooves' second pass drew (every pixel: elsewhere
// the two agree), for the box edges depth-tested after it. Colour targets untouched.
void Renderer::depthFromLinear(const FrameUniforms& f) {
  Gl& g = *gl_;
  const GLenum none[] = {GL_NONE, GL_NONE, GL_NONE, GL_NONE};
  glNamedFramebufferDrawBuffers(g.fbo, 4, none);
  glDepthFunc(GL_ALWAYS);
  glUseProgram(g.grooveDepth);
  glUniform1f(glGetUniformLocation(g.grooveDepth, "nearPlane"), float(f.nearPlane));
  glBindTextureUnit(12, g.linearTex);
  glBindVertexArray(g.vao);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  glDepthFunc(GL_GREATER);
}

void Renderer::readDeferred(FrameStats& st) {
  GLuint n[2] = {0, 0};
  glGetNamedBufferSubData(gl_->deferBuf, 4 * kDeferCountAt, sizeof(n), n);
  st.deferred = n[0];
  st.undeferred = n[1];
}

void Renderer::drawPoints(const Camera& cam, const FrameUniforms& f, const RenderSettings& s, FrameStats& st) {
  Gl& g = *gl_;
  setCommonUniforms(g.points, f, s);
  const double ty = std::tan(cam.fovDeg * M_PI / 360.0);
  glUniform1f(glGetUniformLocation(g.points, "spacingPixels"), float(spacing_ * cam.height / (2 * ty)));
  glEnable(GL_PROGRAM_POINT_SIZE);
  glDisable(GL_CULL_FACE);
  glBindVertexArray(g.pointVao);
  glDrawArrays(GL_POINTS, 0, GLsizei(pointCount_));
  st.points = pointCount_;
}

// Eye-dome lighting into the post-processing target.
void Renderer::drawEdl(const RenderSettings& s) {
  Gl& g = *gl_;
  glBindFramebuffer(GL_FRAMEBUFFER, g.postFbo);
  glDisable(GL_DEPTH_TEST);
  glUseProgram(g.edl);
  glUniform1f(glGetUniformLocation(g.edl, "strength"), s.edlStrength);
  glUniform1f(glGetUniformLocation(g.edl, "radius"), s.edlRadius);
  glBindTextureUnit(0, g.colorTex);
  glBindTextureUnit(1, g.linearTex);
  glBindVertexArray(g.vao);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  glEnable(GL_DEPTH_TEST);
}

// Copies what was asked for out of the framebuffer, rows flipped so row 0 is the top.
void Renderer::readBack(const Camera& cam, unsigned what, FrameResult& out) {
  Gl& g = *gl_;
  auto readFlipped = [&](GLenum attachment, GLenum format, GLenum type, size_t pixelBytes, void* dst) {
    std::vector<uint8_t> rows(size_t(cam.width) * cam.height * pixelBytes);
    const bool post = attachment == GL_COLOR_ATTACHMENT0 && g.lastWasPost;
    glBindFramebuffer(GL_READ_FRAMEBUFFER, post ? g.postFbo : g.fbo);
    glNamedFramebufferReadBuffer(post ? g.postFbo : g.fbo, attachment);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadPixels(0, 0, cam.width, cam.height, format, type, rows.data());
    const size_t stride = size_t(cam.width) * pixelBytes;
    for (int y = 0; y < cam.height; ++y)
      std::memcpy(static_cast<uint8_t*>(dst) + size_t(y) * stride, &rows[size_t(cam.height - 1 - y) * stride], stride);
  };
  const size_t n = size_t(cam.width) * cam.height;
  if (what & kReadColor) {
    out.color.width = cam.width;
    out.color.height = cam.height;
    out.color.rgba.resize(n * 4);
    readFlipped(GL_COLOR_ATTACHMENT0, GL_RGBA, GL_UNSIGNED_BYTE, 4, out.color.rgba.data());
  }
  if (what & kReadDepth) {
    out.depth.resize(n);
    readFlipped(GL_COLOR_ATTACHMENT1, GL_RED, GL_FLOAT, 4, out.depth.data());
  }
  if (what & kReadNormals) {
    out.normals.resize(n * 3);
    readFlipped(GL_COLOR_ATTACHMENT2, GL_RGB, GL_FLOAT, 12, out.normals.data());
  }
  if (what & kReadShadow) {
    std::vector<float> rgba(n * 4);
    readFlipped(GL_COLOR_ATTACHMENT2, GL_RGBA, GL_FLOAT, 16, rgba.data());
    out.shadowed.resize(n);
    for (size_t i = 0; i < n; ++i) out.shadowed[i] = rgba[4 * i + 3] > 0.5f ? 1 : 0;
  }
  if (what & kReadCells) {
    out.cells.resize(n);
    readFlipped(GL_COLOR_ATTACHMENT3, GL_RED_INTEGER, GL_UNSIGNED_INT, 4, out.cells.data());
  }
}

Status Renderer::prepareVisible(const Camera& cam, const RenderSettings& s, const Eigen::Vector3d& camRel, double np,
                                VisibleSet& vis, FrameStats& st) {
  Gl& g = *gl_;
  if (s.shadows && !s.headLight) SA_RETURN_IF_ERROR(ensureShadowPrograms(st.drawnMode));
  uploadVisibility(cam, camRel, np, s, vis, st);
  if (g.residency) {
    if (planBudget(cam, camRel, vis, st)) uploadVisibility(cam, camRel, np, s, vis, st);  // with this frame's uploads
  } else if (g.streamer) {
    g.streamer->want(vis.missing);  // the visible cells it lacks, nearest first
  }
  g.lastMissing = uint32_t(vis.missing.size());
  if (s.countWork) glClearNamedBufferData(g.counterBuf, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, nullptr);
  return Status::ok();
}

// Bindings 6 and 7: the drawn mode's own data (GL guarantees only 8 storage-buffer bindings).
void Renderer::bindModeBuffers(RenderMode drawn) {
  Gl& g = *gl_;
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 5, g.counterBuf);
  if (g.mipBuf) {
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 3, g.mipBuf);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 4, g.mipOffBuf);
  }
  if (drawn == RenderMode::kVdm) {
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 6, g.vdmEntryBuf);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 7, g.vdmWordBuf);
  } else if (drawn == RenderMode::kGdm || ((drawn == RenderMode::kSlices || drawn == RenderMode::kAuto) && g.gdmEntryBuf)) {
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 6, g.gdmEntryBuf);  // slices: forced cells slice gdm's voxels
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 7, g.gdmWordBuf);
  } else if (drawn == RenderMode::kGrooves) {
    for (int i = 0; i < 3; ++i) glBindTextureUnit(GLuint(8 + i), g.grooveTex[i]);
    glBindTextureUnit(11, g.cellTex);
  }
}

void Renderer::clearTargets(const Camera& cam, const RenderSettings& s, unsigned readBackMask) {
  Gl& g = *gl_;
  glBindFramebuffer(GL_FRAMEBUFFER, g.fbo);
  glViewport(0, 0, cam.width, cam.height);
  glClipControl(GL_LOWER_LEFT, GL_ZERO_TO_ONE);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_GREATER);
  glDepthMask(GL_TRUE);
  const float bg[4] = {s.background[0], s.background[1], s.background[2], 1.f};
  const float depthInit[4] = {std::numeric_limits<float>::infinity(), 0, 0, 0};
  const float zero4[4] = {0, 0, 0, 0};
  const GLuint noCell[4] = {0, 0, 0, 0};
  glClearNamedFramebufferfv(g.fbo, GL_COLOR, 0, bg);
  glClearNamedFramebufferfv(g.fbo, GL_COLOR, 1, depthInit);
  if (readBackMask & (kReadNormals | kReadShadow)) glClearNamedFramebufferfv(g.fbo, GL_COLOR, 2, zero4);
  if (readBackMask & kReadCells) glClearNamedFramebufferuiv(g.fbo, GL_COLOR, 3, noCell);
  const float zero = 0.f;
  glClearNamedFramebufferfv(g.fbo, GL_DEPTH, 0, &zero);
}

void Renderer::finishTimings(FrameStats& st, std::chrono::steady_clock::time_point t0) {
  Gl& g = *gl_;
  glFinish();
  st.cpuMs = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  GLuint64 ns = 0, frags = 0;
  glGetQueryObjectui64v(g.timeQuery, GL_QUERY_RESULT, &ns);
  glGetQueryObjectui64v(g.fragQuery, GL_QUERY_RESULT, &frags);
  st.gpuMs = double(ns) / 1e6;
  st.fragments = frags;
}

Status Renderer::render(const Camera& cam, const RenderSettings& s, FrameResult& out, unsigned readBackMask) {
  SA_RETURN_IF_ERROR(cam.validate());
  if (s.mode == RenderMode::kPoints && !hasPoints())
    return Status::badInput("points mode: no source points loaded for this pack");
  Gl& g = *gl_;
  SA_RETURN_IF_ERROR(ensureTargets(cam.width, cam.height));
  // The normal and cell attachments are written only when asked for (eval, tests), so bench
  // frames do not pay.
  const GLenum bufs[] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1,
                         (readBackMask & (kReadNormals | kReadShadow)) ? GLenum(GL_COLOR_ATTACHMENT2) : GLenum(GL_NONE),
                         (readBackMask & kReadCells) ? GLenum(GL_COLOR_ATTACHMENT3) : GLenum(GL_NONE)};
  glNamedFramebufferDrawBuffers(g.fbo, 4, bufs);

  const auto t0 = std::chrono::steady_clock::now();
  uploadTiles(uint64_t(64) << 20);  // streamed packs: up to 64 MiB of tiles a frame
  const Eigen::Vector3d camRel = cam.eye - origin_;  // the camera relative to the pack origin, in double
  const double np = nearPlane();
  FrameStats& st = out.stats;
  st = FrameStats{};
  st.fragmentsAreInvocations = g.fragTarget == GL_FRAGMENT_SHADER_INVOCATIONS_ARB;
  st.drawnMode = drawnMode(s.mode);
  const bool surface = s.mode != RenderMode::kPoints;
  VisibleSet vis;
  if (surface) SA_RETURN_IF_ERROR(prepareVisible(cam, s, camRel, np, vis, st));
  bindModeBuffers(st.drawnMode);
  clearTargets(cam, s, readBackMask);
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, g.cellBuf);
  glBindTextureUnit(0, g.heightTex);
  glBindTextureUnit(1, g.pageColorTex);
  glBindTextureUnit(2, g.normalTex);
  const FrameUniforms f = frameUniforms(cam, s, camRel, np);
  glBeginQuery(GL_TIME_ELAPSED, g.timeQuery);
  glBeginQuery(g.fragTarget, g.fragQuery);
  if (surface) drawCells(vis, f, s, bufs);
  else drawPoints(cam, f, s, st);
  g.lastWasPost = s.edl;
  if (s.edl) drawEdl(s);
  glEndQuery(g.fragTarget);
  glEndQuery(GL_TIME_ELAPSED);
  finishTimings(st, t0);
  if (surface && s.countWork) readCounters(st.work);
  if (surface && st.drawnMode == RenderMode::kGrooves && (!ownLists_[0].empty() || !ownLists_[1].empty())) readDeferred(st);
  out.milliseconds = st.cpuMs;
  out.cellsDrawn = st.drawn;
  readBack(cam, readBackMask, out);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  const GLenum err = glGetError();
  if (err != GL_NO_ERROR) return Status::internal("OpenGL error " + std::to_string(err) + " while rendering");
  return Status::ok();
}

float Renderer::depthAt(int x, int y) const {
  const Gl& g = *gl_;
  if (!g.fbo || x < 0 || y < 0 || x >= g.fbW || y >= g.fbH) return std::numeric_limits<float>::infinity();
  float d = 0;
  glBindFramebuffer(GL_READ_FRAMEBUFFER, g.fbo);
  glNamedFramebufferReadBuffer(g.fbo, GL_COLOR_ATTACHMENT1);
  glReadPixels(x, g.fbH - 1 - y, 1, 1, GL_RED, GL_FLOAT, &d);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
  return d;
}

void Renderer::present(int width, int height) const {
  const Gl& g = *gl_;
  if (!g.fbo) return;
  const GLuint src = g.lastWasPost ? g.postFbo : g.fbo;
  glNamedFramebufferReadBuffer(src, GL_COLOR_ATTACHMENT0);
  glBlitNamedFramebuffer(src, 0, 0, 0, g.fbW, g.fbH, 0, 0, width, height, GL_COLOR_BUFFER_BIT, GL_NEAREST);
}

}  // namespace sa
