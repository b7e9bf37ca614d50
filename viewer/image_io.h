// PNG (libpng), JPEG (stb_image_write) and PFM output, written atomically.
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
// By the file's extension: .png (libpng) or .jpg / .jpeg (stb_image_write, quality 92);
// any other extension is a bad-input error naming the file.
Status writeImage(const std::string& path, const Image& img);
// Checks the extension writeImage needs, before any work.
Status checkImageExtension(const std::string& path);
Result<Image> readPng(const std::string& path);
// Single-channel float PFM ("Pf"), little-endian; depth row 0 is the top row of the image.
Status writePfm(const std::string& path, int width, int height, const std::vector<float>& values);
Result<std::vector<float>> readPfm(const std::string& path, int& width, int& height);

}  // namespace sa
