#include "viewer/egl_context.h"

#include "viewer/tile_cache.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

namespace sa {
namespace {

bool tryDisplay(EGLDisplay dpy, void*& outCtx, std::string& renderer) {
  if (dpy == EGL_NO_DISPLAY) return false;
  EGLint major = 0, minor = 0;
  if (!eglInitialize(dpy, &major, &minor)) return false;
  if (!eglBindAPI(EGL_OPENGL_API)) return false;
  const EGLint ctxAttr[] = {EGL_CONTEXT_MAJOR_VERSION, 4, EGL_CONTEXT_MINOR_VERSION, 5,
                            EGL_CONTEXT_OPENGL_PROFILE_MASK, EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
  EGLConfig cfg = nullptr;
  const EGLint cfgAttr[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
  EGLint n = 0;
  eglChooseConfig(dpy, cfgAttr, &cfg, 1, &n);
  EGLContext ctx = eglCreateContext(dpy, n > 0 ? cfg : EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, ctxAttr);
  if (ctx == EGL_NO_CONTEXT) {
    eglTerminate(dpy);
    return false;
  }
  if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) {
    eglDestroyContext(dpy, ctx);
    eglTerminate(dpy);
    return false;
  }
  outCtx = ctx;
  const char* r = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  renderer = r ? r : "unknown";
  return true;
}

}  // namespace

EglContext::~EglContext() {
  if (display_) {
    eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    if (context_) eglDestroyContext(display_, context_);
    eglTerminate(display_);
  }
}

Status EglContext::init() {
  auto getPlatformDisplay =
      reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
  auto queryDevices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
  const char* force = std::getenv("SCANATLAS_EGL");  // "surfaceless" skips GPU devices
  std::string tried;
  // 1. A hardware device (GPU machines).
  if (getPlatformDisplay && queryDevices && !(force && std::strcmp(force, "surfaceless") == 0)) {
    EGLDeviceEXT devices[16];
    EGLint count = 0;
    if (queryDevices(16, devices, &count)) {
      for (EGLint i = 0; i < count; ++i) {
        EGLDisplay dpy = getPlatformDisplay(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr);
        void* ctx = nullptr;
        std::string r;
        if (!tryDisplay(dpy, ctx, r)) continue;
        if (r.find("llvmpipe") != std::string::npos || r.find("softpipe") != std::string::npos) {
          eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
          eglDestroyContext(dpy, ctx);
          eglTerminate(dpy);
          tried += " device " + std::to_string(i) + " (" + r + ")";
          continue;
        }
        display_ = dpy;
        context_ = ctx;
        renderer_ = r;
        return Status::ok();
      }
    }
  }
  // 2. Mesa's surfaceless platform (CPU rendering with llvmpipe).
  if (getPlatformDisplay) {
    EGLDisplay dpy = getPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    void* ctx = nullptr;
    if (tryDisplay(dpy, ctx, renderer_)) {
      display_ = dpy;
      context_ = ctx;
      return Status::ok();
    }
    tried += " surfaceless";
  }
  // 3. The default display.
  EGLDisplay dpy = eglGetDisplay(EGL_DEFAULT_DISPLAY);
  void* ctx = nullptr;
  if (tryDisplay(dpy, ctx, renderer_)) {
    display_ = dpy;
    context_ = ctx;
    return Status::ok();
  }
  return Status::internal("no OpenGL 4.5 core context could be created through EGL (tried:" + tried +
                          " default). On Debian install libegl-mesa0 and libgl1-mesa-dri (scripts/deps.sh).");
}

uint64_t gpuMemoryBytes() {
  GLint n = 0;
  glGetIntegerv(GL_NUM_EXTENSIONS, &n);
  bool nvx = false, ati = false;
  for (GLint i = 0; i < n; ++i) {
    const char* e = reinterpret_cast<const char*>(glGetStringi(GL_EXTENSIONS, GLuint(i)));
    if (!e) continue;
    nvx = nvx || std::strcmp(e, "GL_NVX_gpu_memory_info") == 0;
    ati = ati || std::strcmp(e, "GL_ATI_meminfo") == 0;
  }
  GLint kib[4] = {0, 0, 0, 0};
  if (nvx) glGetIntegerv(0x9047, kib);  // GPU_MEMORY_INFO_DEDICATED_VIDMEM_NVX, KiB
  else if (ati) glGetIntegerv(0x87FC, kib);  // TEXTURE_FREE_MEMORY_ATI: total free, KiB (first of four)
  while (glGetError() != GL_NO_ERROR) {
  }
  return kib[0] > 0 ? uint64_t(kib[0]) * 1024 : 0;
}

void boundByGpuMemory(GpuBudget& b, const char* tool, bool quiet) {
  if (!b.automatic) return;
  const uint64_t gpu = gpuMemoryBytes();
  b.bytes = defaultGpuBudget(b.atlas, b.ram, gpu);
  if (!b.bytes || quiet) return;
  const double mib = 1048576.0;
  std::fprintf(stderr,
               "%s: the pack's pages (%.0f MiB) are more than a quarter of this machine's memory (%.0f MiB)%s: tiles "
               "stream under a GPU budget of %.0f MiB (--gpu-budget SIZE to choose, --gpu-budget off to upload them all)\n",
               tool, b.atlas / mib, b.ram / mib,
               gpu ? (" or half the GPU's (" + std::to_string(uint64_t(gpu / mib)) + " MiB)").c_str() : "", b.bytes / mib);
}

}  // namespace sa
