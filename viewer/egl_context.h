// A headless OpenGL 4.5 core context through EGL: a GPU device when there is one (EGL device
// platform), otherwise Mesa's surfaceless platform (llvmpipe on CPU-only machines).
#pragma once
#include <cstdint>
#include <string>

#include "common/error.h"

namespace sa {

class EglContext {
 public:
  EglContext() = default;
  ~EglContext();
  EglContext(const EglContext&) = delete;
  EglContext& operator=(const EglContext&) = delete;
  Status init();
  const std::string& renderer() const { return renderer_; }

 private:
  void* display_ = nullptr;
  void* context_ = nullptr;
  std::string renderer_;
};

// The current GL context's GPU memory in bytes where the driver says (GL_NVX_gpu_memory_info:
// the dedicated video memory; GL_ATI_meminfo: the texture memory free now), else 0 (Mesa's
// llvmpipe and most others say nothing).
uint64_t gpuMemoryBytes();

struct GpuBudget;
// A default budget (b.automatic) with the current context's GPU memory as well; says on stderr
// (unless quiet) when a default budget applies and why: "<tool>: ...".
void boundByGpuMemory(GpuBudget& b, const char* tool, bool quiet);

}  // namespace sa
