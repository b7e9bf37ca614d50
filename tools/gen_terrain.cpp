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

namespace {

constexpr double kSize = 1000;                       // metres, square
constexpr double kX0 = 636000, kY0 = 848000, kZ0 = 0;  // georeference (metres)
constexpr double kCell = 50;                           // one building per cell at most

struct Building {
  double x0, y0, x1, y1, top;
};

double ground(double x, double y) {
  return 120 + 18 * std::sin(x / 160) * std::cos(y / 210) + 4 * std::sin(x / 37 + y / 53) + 1.5 * std::cos(x / 11 - y / 17);
}

void groundNormal(double x, double y, float n[3]) {
  const double e = 0.01;
  const double gx = (ground(x + e, y) - ground(x - e, y)) / (2 * e), gy = (ground(x, y + e) - ground(x, y - e)) / (2 * e);
  const double l = std::sqrt(gx * gx + gy * gy + 1);
  n[0] = float(-gx / l), n[1] = float(-gy / l), n[2] = float(1 / l);
}

struct Point {
  double x, y, z;
  float n[3];
  uint16_t rgb[3];
};

struct Scene {
  std::vector<Building> b;
  std::vector<double> wallCum;  // cumulative wall area per building
  double groundArea = kSize * kSize, wallArea = 0;

  Scene() {
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> u(0, 1);
    const int cells = int(kSize / kCell);
    for (int j = 0; j < cells; ++j)
      for (int i = 0; i < cells; ++i) {
        if (u(rng) < 0.55) continue;
        const double w = 10 + 25 * u(rng), h = 10 + 25 * u(rng);
        const double x0 = i * kCell + (kCell - w) * u(rng), y0 = j * kCell + (kCell - h) * u(rng);
        double base = 1e300;
        for (double a : {0.0, 1.0})
          for (double c : {0.0, 1.0}) base = std::min(base, ground(x0 + a * w, y0 + c * h));
        b.push_back({x0, y0, x0 + w, y0 + h, base + 4 + 26 * u(rng) * u(rng)});
      }
    for (const Building& k : b) {
      // Walls from the lowest ground corner up (the part below the ground is never sampled).
      wallArea += 2 * ((k.x1 - k.x0) + (k.y1 - k.y0)) * (k.top - ground(k.x0, k.y0));
      wallCum.push_back(wallArea);
    }
  }

  const Building* roofAt(double x, double y) const {
    const int i = int(x / kCell), j = int(y / kCell);
    for (const Building& k : b)  // few per row: a linear scan over the candidates is enough
      if (int(k.x0 / kCell) == i && int(k.y0 / kCell) == j && x >= k.x0 && x <= k.x1 && y >= k.y0 && y <= k.y1) return &k;
    return nullptr;
  }

  Point sample(std::mt19937_64& rng) const {
    std::uniform_real_distribution<double> u(0, 1);
    std::normal_distribution<double> noise(0, 0.03);
    Point p{};
    if (u(rng) * (groundArea + wallArea) < wallArea) {
      const double a = u(rng) * wallArea;
      size_t k = size_t(std::lower_bound(wallCum.begin(), wallCum.end(), a) - wallCum.begin());
      const Building& w = b[std::min(k, b.size() - 1)];
      const double per = 2 * ((w.x1 - w.x0) + (w.y1 - w.y0));
      double s = u(rng) * per;
      const double lenX = w.x1 - w.x0, lenY = w.y1 - w.y0;
      if (s < lenX) p.x = w.x0 + s, p.y = w.y0, p.n[1] = -1;
      else if ((s -= lenX) < lenY) p.x = w.x1, p.y = w.y0 + s, p.n[0] = 1;
      else if ((s -= lenY) < lenX) p.x = w.x1 - s, p.y = w.y1, p.n[1] = 1;
      else p.x = w.x0, p.y = w.y1 - (s - lenX), p.n[0] = -1;
      const double g = ground(p.x, p.y);
      p.z = g + u(rng) * (w.top - g);
      p.x += noise(rng) * (p.n[0] != 0), p.y += noise(rng) * (p.n[1] != 0);
      p.rgb[0] = 52000, p.rgb[1] = 50000, p.rgb[2] = 46000;  // plaster
      if (p.z < g) p.z = g;
      return p;
    }
    p.x = u(rng) * kSize, p.y = u(rng) * kSize;
    if (const Building* r = roofAt(p.x, p.y)) {
      p.z = r->top + noise(rng);
      p.n[2] = 1;
      p.rgb[0] = 40000, p.rgb[1] = 14000, p.rgb[2] = 12000;  // tiles
      return p;
    }
    p.z = ground(p.x, p.y) + noise(rng);
    groundNormal(p.x, p.y, p.n);
    const double t = std::clamp((p.z - 100) / 45, 0.0, 1.0);
    p.rgb[0] = uint16_t(18000 + 20000 * t), p.rgb[1] = uint16_t(36000 - 6000 * t), p.rgb[2] = uint16_t(12000 + 8000 * t);
    return p;
  }
};

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
    put<double>(h, 179, kX0 + kSize), put<double>(h, 187, kX0);  // max x, min x
    put<double>(h, 195, kY0 + kSize), put<double>(h, 203, kY0);
    put<double>(h, 211, 300.0), put<double>(h, 219, 0.0);
    std::fwrite(h.data(), 1, h.size(), f);
  } else {
    std::fprintf(f, "ply\nformat binary_little_endian 1.0\ncomment synthetic survey, scanatlas tools/gen_terrain\n"
                    "element vertex %llu\nproperty double x\nproperty double y\nproperty double z\n"
                    "property float nx\nproperty float ny\nproperty float nz\n"
                    "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n", n);
  }
  std::mt19937_64 rng(11);
  std::vector<char> buf;
  for (unsigned long long i = 0; i < n; ++i) {
    const Point p = scene.sample(rng);
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
  return std::fclose(f) == 0 ? 0 : 1;
}
