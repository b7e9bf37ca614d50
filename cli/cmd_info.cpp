#include <cstdio>
#include <map>

#include "atlas/pack_file.h"
#include "cli/args.h"
#include "cli/commands.h"

namespace sa {

int cmdInfo(int argc, char** argv) {
  Args a;
  Status s = a.parse(argc, argv, {}, {"json", "help"}, {{"h", "help"}});
  if (a.flag("help")) {
    std::fputs("usage: scanatlas info PACK [--json]\n\n"
               "Describes a pack: cells per octree level, texels, pages, bytes, bounds, the sample\n"
               "spacing and texel size, and how long each packing phase took.\n",
               stdout);
    return 0;
  }
  if (!s) return reportError(s);
  if (a.positionals().size() != 1) return reportError(Status::badInput("info: give exactly one pack (see --help)"));
  PackReader pack;
  s = pack.open(a.positionals()[0]);
  if (!s) return reportError(s);
  const PackMeta& m = pack.meta();
  std::map<int, uint32_t> perLevel;
  uint32_t forced = 0, degenerate = 0;
  uint64_t tileTexels = 0;
  for (const CellRecord& c : pack.cells()) {
    ++perLevel[c.level];
    forced += (c.flags & kCellForced) != 0;
    degenerate += (c.flags & kCellDegenerate) != 0;
    tileTexels += uint64_t(c.tileW) * c.tileH;
  }
  const uint64_t pageTexels = uint64_t(m.pageSize) * m.pageSize * m.pageCount;
  double bmin[3], bmax[3];
  for (int i = 0; i < 3; ++i) {
    bmin[i] = m.origin[i] + m.boundsMin[i];
    bmax[i] = m.origin[i] + m.boundsMax[i];
  }
  const char* phases[6] = {"count", "distribute", "octree", "heightmaps", "write", "total"};
  if (a.flag("json")) {
    std::printf("{\"file\": \"%s\", \"bytes\": %llu, \"cells\": %u, \"forced_cells\": %u, \"degenerate_cells\": %u, "
                "\"levels\": {",
                jsonEscape(pack.path()).c_str(), (unsigned long long)pack.fileBytes(), m.cellCount, forced, degenerate);
    bool first = true;
    for (auto [l, n] : perLevel) {
      std::printf("%s\"%d\": %u", first ? "" : ", ", l, n);
      first = false;
    }
    std::printf("}, \"texels\": %llu, \"page_size\": %u, \"pages\": %u, \"atlas_occupancy\": %.4f, "
                "\"texel_size\": %.9g, \"sample_spacing\": %.9g, \"source_points\": %llu, \"skipped_points\": %llu, "
                "\"source_triangles\": %llu, \"color\": %s, \"bytes_per_point\": %.3f, "
                "\"origin\": [%.17g, %.17g, %.17g], \"bounds_min\": [%.17g, %.17g, %.17g], "
                "\"bounds_max\": [%.17g, %.17g, %.17g], \"seconds\": {",
                (unsigned long long)tileTexels, m.pageSize, m.pageCount, double(tileTexels) / double(pageTexels),
                m.texelSize, m.sampleSpacing, (unsigned long long)m.sourcePoints, (unsigned long long)m.skippedPoints,
                (unsigned long long)m.sourceTriangles, pack.hasColor() ? "true" : "false",
                double(pack.fileBytes()) / double(std::max<uint64_t>(1, m.sourcePoints)), m.origin[0], m.origin[1],
                m.origin[2], bmin[0], bmin[1], bmin[2], bmax[0], bmax[1], bmax[2]);
    for (int i = 0; i < 6; ++i) std::printf("%s\"%s\": %.3f", i ? ", " : "", phases[i], m.seconds[i]);
    std::printf("}}\n");
    return 0;
  }
  std::printf("pack      %s (%.2f MiB, format version %u)\n", pack.path().c_str(), pack.fileBytes() / 1048576.0,
              kPackVersion);
  std::printf("source    %llu points (%llu NaN/Inf skipped), %llu triangles, %s, %s\n",
              (unsigned long long)m.sourcePoints, (unsigned long long)m.skippedPoints,
              (unsigned long long)m.sourceTriangles, (m.flags & kPackFromTriangles) ? "heights rasterized" : "heights by pull-push",
              pack.hasColor() ? "with colour" : "no colour");
  std::printf("bounds    [%.6f, %.6f, %.6f] .. [%.6f, %.6f, %.6f]\n", bmin[0], bmin[1], bmin[2], bmax[0], bmax[1], bmax[2]);
  std::printf("cells     %u (%u forced, %u degenerate), %u chunk(s)\n", m.cellCount, forced, degenerate, m.chunkCount);
  std::printf("levels   ");
  for (auto [l, n] : perLevel) std::printf(" L%d:%u", l, n);
  std::printf("\n");
  std::printf("texels    %llu in %u page(s) of %u^2 (occupancy %.1f%%), texel %.4g, sample spacing %.4g\n",
              (unsigned long long)tileTexels, m.pageCount, m.pageSize, 100.0 * double(tileTexels) / double(pageTexels),
              m.texelSize, m.sampleSpacing);
  std::printf("bytes     %.2f per source point\n", double(pack.fileBytes()) / double(std::max<uint64_t>(1, m.sourcePoints)));
  std::printf("timings  ");
  for (int i = 0; i < 6; ++i)
    if (i != 4) std::printf(" %s %.2fs", phases[i], m.seconds[i]);
  std::printf("\n");
  return 0;
}

}  // namespace sa
