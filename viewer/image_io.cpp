#include "viewer/image_io.h"

#include <png.h>
#include <stb/stb_image_write.h>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "common/fileio.h"

namespace sa {

Status writePng(const std::string& path, const Image& img) {
  png_image pi;
  std::memset(&pi, 0, sizeof(pi));
  pi.version = PNG_IMAGE_VERSION;
  pi.width = static_cast<png_uint_32>(img.width);
  pi.height = static_cast<png_uint_32>(img.height);
  pi.format = PNG_FORMAT_RGBA;
  png_alloc_size_t size = 0;
  if (!png_image_write_to_memory(&pi, nullptr, &size, 0, img.rgba.data(), 0, nullptr))
    return Status::internal(path + ": PNG encoding failed");
  std::vector<uint8_t> buf(size);
  if (!png_image_write_to_memory(&pi, buf.data(), &size, 0, img.rgba.data(), 0, nullptr))
    return Status::internal(path + ": PNG encoding failed: " + pi.message);
  return writeFileAtomic(path, buf.data(), size);
}

Status checkImageExtension(const std::string& path) {
  const std::string ext = lowerExtension(path);
  if (ext == ".png" || ext == ".jpg" || ext == ".jpeg") return Status::ok();
  return Status::badInput(path + ": unknown image type '" + ext + "'; write .png or .jpg");
}

Status writeImage(const std::string& path, const Image& img) {
  SA_RETURN_IF_ERROR(checkImageExtension(path));
  if (lowerExtension(path) == ".png") return writePng(path, img);
  std::vector<uint8_t> buf;
  auto sink = [](void* ctx, void* data, int size) {
    auto* b = static_cast<std::vector<uint8_t>*>(ctx);
    b->insert(b->end(), static_cast<uint8_t*>(data), static_cast<uint8_t*>(data) + size);
  };
  if (!stbi_write_jpg_to_func(sink, &buf, img.width, img.height, 4, img.rgba.data(), 92))
    return Status::internal(path + ": JPEG encoding failed");
  return writeFileAtomic(path, buf.data(), buf.size());
}

Result<Image> readPng(const std::string& path) {
  png_image pi;
  std::memset(&pi, 0, sizeof(pi));
  pi.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&pi, path.c_str())) return Status::badInput(path + ": not a readable PNG");
  pi.format = PNG_FORMAT_RGBA;
  Image img;
  img.width = static_cast<int>(pi.width);
  img.height = static_cast<int>(pi.height);
  img.rgba.resize(PNG_IMAGE_SIZE(pi));
  if (!png_image_finish_read(&pi, nullptr, img.rgba.data(), 0, nullptr))
    return Status::badInput(path + ": PNG decoding failed: " + pi.message);
  return img;
}

Status writePfm(const std::string& path, int width, int height, const std::vector<float>& values) {
  std::ostringstream os;
  os << "Pf\n" << width << " " << height << "\n-1.0\n";
  std::string data = os.str();
  const size_t head = data.size();
  data.resize(head + size_t(width) * height * 4);
  // PFM stores rows bottom to top.
  for (int y = 0; y < height; ++y)
    std::memcpy(&data[head + size_t(y) * width * 4], &values[size_t(height - 1 - y) * width], size_t(width) * 4);
  return writeFileAtomic(path, data.data(), data.size());
}

Result<std::vector<float>> readPfm(const std::string& path, int& width, int& height) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::badInput(path + ": cannot open");
  std::string magic;
  double scale;
  in >> magic >> width >> height >> scale;
  in.get();
  if (magic != "Pf" || width <= 0 || height <= 0 || width > 65536 || height > 65536 || scale >= 0)
    return Status::badInput(path + ": not a little-endian single-channel PFM");
  std::vector<float> rows(size_t(width) * height), out(size_t(width) * height);
  if (!in.read(reinterpret_cast<char*>(rows.data()), std::streamsize(rows.size() * 4)))
    return Status::badInput(path + ": truncated PFM");
  for (int y = 0; y < height; ++y)
    std::memcpy(&out[size_t(y) * width], &rows[size_t(height - 1 - y) * width], size_t(width) * 4);
  return out;
}

}  // namespace sa
