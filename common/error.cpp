#include "common/error.h"

namespace sa {
void checkFailed(const char* expr, const char* file, int line) {
  std::fprintf(stderr, "internal error: check failed: %s at %s:%d\n", expr, file, line);
  std::abort();
}
}  // namespace sa
