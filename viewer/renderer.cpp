#include "viewer/renderer.h"

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

namespace sa {
namespace {

// Expands `#include "name"` lines with the embedded files (one level is all we use).
std::string shaderSource(const std::string& name) {
  const char* text = embeddedShader(name);
  if (!text) return {};
  std::istringstream in(text);
  std::string line, out;
  while (std::getline(in, line)) {
    if (line.rfind("#include \"", 0) == 0) {
      const std::string inc = line.substr(10, line.find('"', 10) - 10);
      const char* body = embeddedShader(inc);
      out += body ? body : "#error missing include " + inc;
      out += "\n";
    } else {
      out += line + "\n";
    }
  }
  return out;
}

Status compile(GLenum type, const std::string& name, GLuint& shader) {
  const std::string src = shaderSource(name);
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

struct GpuCell {
  float originHi[4], originLo[4], u[4], v[4], w[4], boxUV[4], boxW[4];
  int32_t tile[4];
};
static_assert(sizeof(GpuCell) == 128);

void splitDouble(double d, float& hi, float& lo) {
  hi = static_cast<float>(d);
  lo = static_cast<float>(d - static_cast<double>(hi));
}

}  // namespace

struct Renderer::Gl {
  GLuint program = 0, vao = 0, ssbo = 0, heightTex = 0, colorTex = 0, dummyColor = 0;
  GLuint fbo = 0, colorRb = 0, depthRb = 0, linearRb = 0;
  int fbW = 0, fbH = 0;
  ~Gl() {
    if (program) glDeleteProgram(program);
    if (vao) glDeleteVertexArrays(1, &vao);
    if (ssbo) glDeleteBuffers(1, &ssbo);
    GLuint tex[] = {heightTex, colorTex, dummyColor};
    glDeleteTextures(3, tex);
    if (fbo) glDeleteFramebuffers(1, &fbo);
    GLuint rb[] = {colorRb, depthRb, linearRb};
    glDeleteRenderbuffers(3, rb);
  }
};

Renderer::Renderer() = default;
Renderer::~Renderer() = default;

Status Renderer::init(const PackReader& pack) {
  gl_ = std::make_unique<Gl>();
  const PackMeta& m = pack.meta();
  origin_ = Eigen::Vector3d(m.origin[0], m.origin[1], m.origin[2]);
  boundsMin_ = Eigen::Vector3d(m.boundsMin[0], m.boundsMin[1], m.boundsMin[2]);
  boundsMax_ = Eigen::Vector3d(m.boundsMax[0], m.boundsMax[1], m.boundsMax[2]);
  cellCount_ = m.cellCount;
  hasColor_ = pack.hasColor();
  GLuint vs = 0, fs = 0;
  SA_RETURN_IF_ERROR(compile(GL_VERTEX_SHADER, "box.vert", vs));
  SA_RETURN_IF_ERROR(compile(GL_FRAGMENT_SHADER, "parallax.frag", fs));
  gl_->program = glCreateProgram();
  glAttachShader(gl_->program, vs);
  glAttachShader(gl_->program, fs);
  glLinkProgram(gl_->program);
  glDeleteShader(vs);
  glDeleteShader(fs);
  GLint ok = 0;
  glGetProgramiv(gl_->program, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[4096];
    glGetProgramInfoLog(gl_->program, sizeof(log), nullptr, log);
    return Status::internal(std::string("shader program failed to link:\n") + log);
  }
  glCreateVertexArrays(1, &gl_->vao);

  std::vector<GpuCell> cells(m.cellCount);
  auto src = pack.cells();
  for (uint32_t i = 0; i < m.cellCount; ++i) {
    const CellRecord& c = src[i];
    GpuCell& g = cells[i];
    std::memset(&g, 0, sizeof(g));
    for (int a = 0; a < 3; ++a) {
      splitDouble(c.origin[a], g.originHi[a], g.originLo[a]);
      g.u[a] = float(c.u[a]);
      g.v[a] = float(c.v[a]);
      g.w[a] = float(c.w[a]);
    }
    for (int a = 0; a < 4; ++a) g.boxUV[a] = float(c.box[a]);
    g.boxW[0] = float(c.box[4]);
    g.boxW[1] = float(c.box[5]);
    g.boxW[2] = float(c.tileW);
    g.boxW[3] = float(c.tileH);
    g.tile[0] = int32_t(c.page);
    g.tile[1] = int32_t(c.tileX);
    g.tile[2] = int32_t(c.tileY);
    g.tile[3] = c.flags;
  }
  glCreateBuffers(1, &gl_->ssbo);
  glNamedBufferStorage(gl_->ssbo, GLsizeiptr(std::max<size_t>(1, cells.size()) * sizeof(GpuCell)),
                       cells.empty() ? nullptr : cells.data(), 0);
  gpuBytes_ = cells.size() * sizeof(GpuCell);

  GLint maxLayers = 0, maxSize = 0;
  glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &maxLayers);
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &maxSize);
  if (GLint(m.pageCount) > maxLayers || GLint(m.pageSize) > maxSize)
    return Status::internal(pack.path() + ": atlas needs " + std::to_string(m.pageCount) + " layers of " +
                            std::to_string(m.pageSize) + "^2 but the GL allows " + std::to_string(maxLayers) +
                            " layers of " + std::to_string(maxSize) + "^2");
  glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &gl_->heightTex);
  glTextureStorage3D(gl_->heightTex, 1, GL_R16UI, GLsizei(m.pageSize), GLsizei(m.pageSize), GLsizei(m.pageCount));
  for (uint32_t p = 0; p < m.pageCount; ++p)
    glTextureSubImage3D(gl_->heightTex, 0, 0, 0, GLint(p), GLsizei(m.pageSize), GLsizei(m.pageSize), 1,
                        GL_RED_INTEGER, GL_UNSIGNED_SHORT, pack.heightPage(p));
  glTextureParameteri(gl_->heightTex, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTextureParameteri(gl_->heightTex, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  gpuBytes_ += uint64_t(m.pageSize) * m.pageSize * m.pageCount * 2;
  glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &gl_->colorTex);
  if (hasColor_) {
    glTextureStorage3D(gl_->colorTex, 1, GL_RGBA8, GLsizei(m.pageSize), GLsizei(m.pageSize), GLsizei(m.pageCount));
    for (uint32_t p = 0; p < m.pageCount; ++p)
      glTextureSubImage3D(gl_->colorTex, 0, 0, 0, GLint(p), GLsizei(m.pageSize), GLsizei(m.pageSize), 1, GL_RGBA,
                          GL_UNSIGNED_BYTE, pack.colorPage(p));
    gpuBytes_ += uint64_t(m.pageSize) * m.pageSize * m.pageCount * 4;
  } else {
    const uint8_t white[4] = {255, 255, 255, 255};
    glTextureStorage3D(gl_->colorTex, 1, GL_RGBA8, 1, 1, 1);
    glTextureSubImage3D(gl_->colorTex, 0, 0, 0, 0, 1, 1, 1, GL_RGBA, GL_UNSIGNED_BYTE, white);
  }
  glTextureParameteri(gl_->colorTex, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTextureParameteri(gl_->colorTex, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  if (glGetError() != GL_NO_ERROR) return Status::internal("OpenGL error while uploading the pack (out of memory?)");
  return Status::ok();
}

Status Renderer::render(const Camera& cam, const RenderSettings& s, FrameResult& out, bool readDepth) {
  SA_RETURN_IF_ERROR(cam.validate());
  Gl& g = *gl_;
  if (g.fbW != cam.width || g.fbH != cam.height) {
    if (g.fbo) glDeleteFramebuffers(1, &g.fbo);
    GLuint rb[] = {g.colorRb, g.depthRb, g.linearRb};
    glDeleteRenderbuffers(3, rb);
    glCreateFramebuffers(1, &g.fbo);
    glCreateRenderbuffers(1, &g.colorRb);
    glCreateRenderbuffers(1, &g.depthRb);
    glCreateRenderbuffers(1, &g.linearRb);
    glNamedRenderbufferStorage(g.colorRb, GL_RGBA8, cam.width, cam.height);
    glNamedRenderbufferStorage(g.linearRb, GL_R32F, cam.width, cam.height);
    glNamedRenderbufferStorage(g.depthRb, GL_DEPTH_COMPONENT32F, cam.width, cam.height);
    glNamedFramebufferRenderbuffer(g.fbo, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, g.colorRb);
    glNamedFramebufferRenderbuffer(g.fbo, GL_COLOR_ATTACHMENT1, GL_RENDERBUFFER, g.linearRb);
    glNamedFramebufferRenderbuffer(g.fbo, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, g.depthRb);
    const GLenum bufs[] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
    glNamedFramebufferDrawBuffers(g.fbo, 2, bufs);
    if (glCheckNamedFramebufferStatus(g.fbo, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
      return Status::internal("framebuffer incomplete at " + std::to_string(cam.width) + "x" + std::to_string(cam.height));
    g.fbW = cam.width;
    g.fbH = cam.height;
  }
  // Camera relative to the pack origin, in double, then split for the GPU.
  const Eigen::Vector3d camRel = cam.eye - origin_;
  float hi[3], lo[3];
  for (int a = 0; a < 3; ++a) splitDouble(camRel[a], hi[a], lo[a]);
  const double radius = std::max((boundsMax_ - boundsMin_).norm() / 2, 1e-12);
  const double nearPlane = radius * 1e-5;
  const Eigen::Matrix3f rot = cam.viewRotation().cast<float>();
  const Eigen::Matrix4f proj = cam.projection(nearPlane).cast<float>();
  const Eigen::Vector3f fwd = cam.forward().cast<float>();

  const auto t0 = std::chrono::steady_clock::now();
  glBindFramebuffer(GL_FRAMEBUFFER, g.fbo);
  glViewport(0, 0, cam.width, cam.height);
  glClipControl(GL_LOWER_LEFT, GL_ZERO_TO_ONE);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_GREATER);
  glDepthMask(GL_TRUE);
  glEnable(GL_CULL_FACE);
  glCullFace(GL_FRONT);  // back faces: a camera inside a box still gets its fragments
  const float bg[4] = {s.background[0], s.background[1], s.background[2], 1.f};
  const float inf = std::numeric_limits<float>::infinity();
  const float depthInit[4] = {inf, 0, 0, 0};
  glClearNamedFramebufferfv(g.fbo, GL_COLOR, 0, bg);
  glClearNamedFramebufferfv(g.fbo, GL_COLOR, 1, depthInit);
  const float zero = 0.f;
  glClearNamedFramebufferfv(g.fbo, GL_DEPTH, 0, &zero);
  glUseProgram(g.program);
  glUniformMatrix3fv(glGetUniformLocation(g.program, "viewRotation"), 1, GL_FALSE, rot.data());
  glUniformMatrix4fv(glGetUniformLocation(g.program, "projection"), 1, GL_FALSE, proj.data());
  glUniform3fv(glGetUniformLocation(g.program, "camHi"), 1, hi);
  glUniform3fv(glGetUniformLocation(g.program, "camLo"), 1, lo);
  glUniform1i(glGetUniformLocation(g.program, "iterations"), std::max(1, s.iterations));
  glUniform1i(glGetUniformLocation(g.program, "refineSteps"), std::max(0, s.refineSteps));
  glUniform1f(glGetUniformLocation(g.program, "nearPlane"), float(nearPlane));
  glUniform3fv(glGetUniformLocation(g.program, "viewForward"), 1, fwd.data());
  glUniform1i(glGetUniformLocation(g.program, "useColor"), s.useColor && hasColor_ ? 1 : 0);
  glUniform3fv(glGetUniformLocation(g.program, "baseColor"), 1, s.baseColor);
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, g.ssbo);
  glBindTextureUnit(0, g.heightTex);
  glBindTextureUnit(1, g.colorTex);
  glBindVertexArray(g.vao);
  if (cellCount_ > 0) glDrawArraysInstanced(GL_TRIANGLES, 0, 36, GLsizei(cellCount_));
  glFinish();
  out.milliseconds = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  out.cellsDrawn = cellCount_;

  out.color.width = cam.width;
  out.color.height = cam.height;
  out.color.rgba.resize(size_t(cam.width) * cam.height * 4);
  std::vector<uint8_t> rows(out.color.rgba.size());
  glNamedFramebufferReadBuffer(g.fbo, GL_COLOR_ATTACHMENT0);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, cam.width, cam.height, GL_RGBA, GL_UNSIGNED_BYTE, rows.data());
  const size_t stride = size_t(cam.width) * 4;
  for (int y = 0; y < cam.height; ++y)
    std::memcpy(&out.color.rgba[size_t(y) * stride], &rows[size_t(cam.height - 1 - y) * stride], stride);
  if (readDepth) {
    std::vector<float> d(size_t(cam.width) * cam.height);
    glNamedFramebufferReadBuffer(g.fbo, GL_COLOR_ATTACHMENT1);
    glReadPixels(0, 0, cam.width, cam.height, GL_RED, GL_FLOAT, d.data());
    out.depth.resize(d.size());
    for (int y = 0; y < cam.height; ++y)
      std::memcpy(&out.depth[size_t(y) * cam.width], &d[size_t(cam.height - 1 - y) * cam.width], size_t(cam.width) * 4);
  }
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  const GLenum err = glGetError();
  if (err != GL_NO_ERROR) return Status::internal("OpenGL error " + std::to_string(err) + " while rendering");
  return Status::ok();
}

}  // namespace sa
