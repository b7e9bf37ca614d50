// Writes a synthetic aerial survey of N points: rolling terrain with box buildings (roofs and
// walls), georeferenced (UTM-like coordinates, millimetre LAS scale), RGB, for packing-throughput
// runs that do not depend on which files a machine has (issue "Scale": the 20 M-point scene).
//
//   sa_gen_terrain N OUT.las            LAS 1.2, point format 2 (RGB), no normals
//   sa_gen_terrain N OUT.ply            binary PLY with normals and RGB: the same scene
//
// The scene is fixed (seeded); N only sets the density, so runs at 2 M and 20 M points compare.
// Points are spread uniformly over the surface area (ground, roofs, walls), with 3 cm noise.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "tools/terrain_scene.h"

namespace {

using namespace sa::gen;

template <class T>
void put(std::vector<char>& h, size_t at, T v) {
  std::memcpy(h.data() + at, &v, sizeof(T));
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: sa_gen_terrain N OUT.las|OUT.ply\n");
    return 2;
  }
  const unsigned long long n = std::strtoull(argv[1], nullptr, 10);
  const std::string path = argv[2];
  const bool las = path.size() > 4 && path.substr(path.size() - 4) == ".las";
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f || n == 0) {
    std::fprintf(stderr, "sa_gen_terrain: cannot write %s (N must be > 0)\n", path.c_str());
    return 1;
  }
  const Scene scene;
  const double scale = 0.001;
  std::vector<char> header;
  if (las) {
    std::vector<char> h(227, 0);
    std::memcpy(h.data(), "LASF", 4);
    h[24] = 1, h[25] = 2;  // version 1.2
    std::strncpy(h.data() + 26, "scanatlas gen_terrain", 32);
    std::strncpy(h.data() + 58, "sa_gen_terrain", 32);
    put<uint16_t>(h, 94, 227);
    put<uint32_t>(h, 96, 227);
    put<uint32_t>(h, 100, 0);
    h[104] = 2;
    put<uint16_t>(h, 105, 26);
    put<uint32_t>(h, 107, uint32_t(std::min<unsigned long long>(n, 0xffffffffull)));
    put<uint32_t>(h, 111, uint32_t(std::min<unsigned long long>(n, 0xffffffffull)));
    for (int k = 0; k < 3; ++k) put<double>(h, 131 + 8 * k, scale);
    put<double>(h, 155, kX0), put<double>(h, 163, kY0), put<double>(h, 171, kZ0);
    std::fwrite(h.data(), 1, h.size(), f);  // bounds written at the end, once known
    header = h;
  } else {
    std::fprintf(f, "ply\nformat binary_little_endian 1.0\ncomment synthetic survey, scanatlas tools/gen_terrain\n"
                    "element vertex %llu\nproperty double x\nproperty double y\nproperty double z\n"
                    "property float nx\nproperty float ny\nproperty float nz\n"
                    "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n", n);
  }
  std::mt19937_64 rng(11);
  std::vector<char> buf;
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (unsigned long long i = 0; i < n; ++i) {
    const Point p = scene.sample(rng);
    const double w[3] = {kX0 + p.x, kY0 + p.y, kZ0 + p.z};
    for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], w[k]), hi[k] = std::max(hi[k], w[k]);
    char rec[64];
    size_t len = 0;
    if (las) {
      const int32_t X = int32_t(std::lround(p.x / scale)), Y = int32_t(std::lround(p.y / scale)), Z = int32_t(std::lround(p.z / scale));
      std::memset(rec, 0, 26);
      std::memcpy(rec, &X, 4), std::memcpy(rec + 4, &Y, 4), std::memcpy(rec + 8, &Z, 4);
      rec[14] = 0x09;                     // return 1 of 1
      rec[15] = p.n[2] == 0 || p.rgb[0] == 40000 ? 6 : 2;  // building / ground
      std::memcpy(rec + 20, p.rgb, 6);
      len = 26;
    } else {
      const double xyz[3] = {kX0 + p.x, kY0 + p.y, kZ0 + p.z};
      std::memcpy(rec, xyz, 24), std::memcpy(rec + 24, p.n, 12);
      for (int k = 0; k < 3; ++k) rec[36 + k] = char(p.rgb[k] >> 8);
      len = 39;
    }
    buf.insert(buf.end(), rec, rec + len);
    if (buf.size() >= (1 << 20) || i + 1 == n) {
      if (std::fwrite(buf.data(), 1, buf.size(), f) != buf.size()) return 1;
      buf.clear();
    }
  }
  if (las) {  // max x, min x, max y, min y, max z, min z
    for (int k = 0; k < 3; ++k) put<double>(header, 179 + 16 * size_t(k), hi[k]), put<double>(header, 187 + 16 * size_t(k), lo[k]);
    if (std::fseek(f, 0, SEEK_SET) != 0 || std::fwrite(header.data(), 1, header.size(), f) != header.size()) return 1;
  }
  return std::fclose(f) == 0 ? 0 : 1;
}
