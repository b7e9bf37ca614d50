// Writes a synthetic groove scan (the detection test's: a tilted, undulating plane with ten known
// V and U grooves, or none) as a binary PLY, and its true grooves as a grooves JSON:
//   sa_gen_grooves OUT.ply TRUTH.json [--size 400] [--spacing 1] [--noise 0.1] [--plain] [--seed 7]
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "grooves/grooves.h"

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: sa_gen_grooves OUT.ply TRUTH.json [--size 400] [--spacing 1] [--noise 0.1] [--plain] [--seed 7]\n");
    return 2;
  }
  double size = 400, spacing = 1, noise = 0.1;
  bool plain = false;
  unsigned seed = 7;
  for (int i = 3; i < argc; ++i) {
    const std::string a = argv[i];
    const bool hasValue = i + 1 < argc;
    if (a == "--plain") plain = true;
    else if (a == "--size" && hasValue) size = std::atof(argv[++i]);
    else if (a == "--spacing" && hasValue) spacing = std::atof(argv[++i]);
    else if (a == "--noise" && hasValue) noise = std::atof(argv[++i]);
    else if (a == "--seed" && hasValue) seed = unsigned(std::atoi(argv[++i]));
    else {
      std::fprintf(stderr, "sa_gen_grooves: unknown option %s\n", a.c_str());
      return 2;
    }
  }
  if (!(size > 10 * spacing) || !(spacing > 0) || !(noise >= 0)) {
    std::fprintf(stderr, "sa_gen_grooves: need size > 10 spacings, spacing > 0, noise >= 0\n");
    return 2;
  }
  const auto grooves = plain ? std::vector<sa::SyntheticGroove>{} : sa::acceptanceGrooves(size, spacing, noise);
  const sa::SyntheticScan scan = sa::makeGrooveScan(size, spacing, noise, grooves, seed);
  std::FILE* f = std::fopen(argv[1], "wb");
  if (!f) {
    std::fprintf(stderr, "sa_gen_grooves: cannot write %s\n", argv[1]);
    return 1;
  }
  const size_t n = scan.pos.size() / 3;
  std::fprintf(f, "ply\nformat binary_little_endian 1.0\ncomment synthetic groove scan, scanatlas tools/gen_grooves\n"
                  "element vertex %zu\nproperty double x\nproperty double y\nproperty double z\nend_header\n", n);
  const bool ok = std::fwrite(scan.pos.data(), sizeof(double), scan.pos.size(), f) == scan.pos.size();
  if (std::fclose(f) != 0 || !ok) {
    std::fprintf(stderr, "sa_gen_grooves: write failed: %s\n", argv[1]);
    return 1;
  }
  sa::GrooveSet truth;
  truth.spacing = spacing;
  truth.noise = noise;
  for (const sa::SyntheticGroove& g : scan.grooves) {
    sa::Groove t;
    for (size_t k = 0; k < g.line.size(); ++k) {
      t.line.push_back(scan.toWorld(g.line[k]));
      if (k) t.length += (g.line[k] - g.line[k - 1]).norm();
    }
    t.width = g.width;
    t.depth = g.depth;
    t.confidence = 1;
    t.shape = g.uncovered ? "gap" : g.rounded ? "U" : "V";
    truth.grooves.push_back(t);
  }
  const sa::Status s = sa::writeGroovesJson(truth, argv[2]);
  if (!s) {
    std::fprintf(stderr, "sa_gen_grooves: %s\n", s.message().c_str());
    return 1;
  }
  std::printf("%zu points, %zu grooves -> %s, %s\n", n, scan.grooves.size(), argv[1], argv[2]);
  return 0;
}
