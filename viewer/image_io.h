// PNG (libpng) and PFM output, written atomically.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "common/error.h"

namespace sa {

struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;  // row 0 at the top
};

Status writePng(const std::string& path, const Image& img);
Result<Image> readPng(const std::string& path);
// Single-channel float PFM ("Pf"), little-endian; depth row 0 is the top row of the image.
Status writePfm(const std::string& path, int width, int height, const std::vector<float>& values);
Result<std::vector<float>> readPfm(const std::string& path, int& width, int& height);

}  // namespace sa
