// Writes a synthetic binary PLY of N points on a closed, detailed surface (a bumpy sphere of
// radius 1 with normals), for throughput and scaling runs: sa_gen_surface N out.ply [--no-normals]
// The same surface at any N, so packs of 1M, 4M and 16M points are comparable.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: sa_gen_surface N OUT.ply [--no-normals]\n");
    return 2;
  }
  const unsigned long long n = std::strtoull(argv[1], nullptr, 10);
  const bool normals = !(argc > 3 && !std::strcmp(argv[3], "--no-normals"));
  std::FILE* f = std::fopen(argv[2], "wb");
  if (!f || n == 0) {
    std::fprintf(stderr, "sa_gen_surface: cannot write %s\n", argv[2]);
    return 1;
  }
  std::fprintf(f, "ply\nformat binary_little_endian 1.0\ncomment synthetic bumpy sphere, scanatlas tools/gen_surface\n"
                  "element vertex %llu\nproperty float x\nproperty float y\nproperty float z\n", n);
  if (normals) std::fprintf(f, "property float nx\nproperty float ny\nproperty float nz\n");
  std::fprintf(f, "end_header\n");
  const double golden = M_PI * (3 - std::sqrt(5.0));
  std::vector<float> buf;
  buf.reserve(6 * 65536);
  for (unsigned long long i = 0; i < n; ++i) {
    const double y = 1 - 2 * (i + 0.5) / double(n);
    const double r = std::sqrt(std::max(0.0, 1 - y * y));
    const double th = golden * double(i);
    const double dx = std::cos(th) * r, dz = std::sin(th) * r;
    // Bumps: radius modulated by a smooth function of the direction.
    const double bump = 0.02 * std::sin(12 * dx) * std::sin(10 * y) * std::sin(11 * dz);
    const double R = 1 + bump;
    buf.insert(buf.end(), {float(R * dx), float(R * y), float(R * dz)});
    if (normals) buf.insert(buf.end(), {float(dx), float(y), float(dz)});
    if (buf.size() >= 6 * 65536 || i + 1 == n) {
      if (std::fwrite(buf.data(), sizeof(float), buf.size(), f) != buf.size()) return 1;
      buf.clear();
    }
  }
  return std::fclose(f) == 0 ? 0 : 1;
}
