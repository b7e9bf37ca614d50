// A headless OpenGL 4.5 core context through EGL: a GPU device when there is one (EGL device
// platform), otherwise Mesa's surfaceless platform (llvmpipe on CPU-only machines).
#pragma once
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

}  // namespace sa
