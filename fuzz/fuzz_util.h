// libFuzzer harness helpers: our readers take paths, so each input goes to a file in /dev/shm.
#pragma once
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include "formats/points.h"

namespace sa::fuzz {

inline std::string writeInput(const uint8_t* data, size_t size, const char* ext) {
  const std::string path = "/dev/shm/scanatlas-fuzz-" + std::to_string(getpid()) + ext;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f) {
    std::fwrite(data, 1, size, f);
    std::fclose(f);
  }
  return path;
}

struct NullSink : BatchSink {
  uint64_t points = 0, triangles = 0;
  Status onPoints(const PointBatch& b) override {
    points += b.size();
    return Status::ok();
  }
  Status onTriangles(const uint32_t*, size_t n) override {
    triangles += n;
    return Status::ok();
  }
};

}  // namespace sa::fuzz
