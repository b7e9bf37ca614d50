#include "atlas/verify.h"

#include <cmath>
#include <cstring>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>

namespace sa {

VerifyReport verifyPack(const PackReader& pack) {
  VerifyReport r;
  auto problem = [&](const std::string& what) {
    if (r.problems.size() < 100) r.problems.push_back(what);
  };
  Status s = pack.verifyPages();
  if (!s) problem(s.message());
  r.sectionsChecked = 1;
  const PackMeta& m = pack.meta();
  const uint32_t P = m.pageWidth;
  // One bit per page texel: tiles with their gutters must not overlap.
  std::vector<std::vector<uint8_t>> used(m.pageCount, std::vector<uint8_t>(size_t(P) * m.pageHeight / 8 + 1, 0));
  uint64_t points = 0;
  auto cells = pack.cells();
  for (uint32_t i = 0; i < cells.size(); ++i) {
    const CellRecord& c = cells[i];
    const std::string name = "cell " + std::to_string(i);
    ++r.cellsChecked;
    points += c.pointCount;
    const Eigen::Vector3d U(c.u), V(c.v), W(c.w);
    const double ortho = std::max({std::abs(U.norm() - 1), std::abs(V.norm() - 1), std::abs(W.norm() - 1),
                                   std::abs(U.dot(V)), std::abs(U.dot(W)), std::abs(V.dot(W))});
    if (!(ortho < 1e-6)) problem(name + ": frame not orthonormal (error " + std::to_string(ortho) + ")");
    if (!(U.cross(V).dot(W) > 0)) problem(name + ": frame is left-handed");
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(c.origin[a])) problem(name + ": origin not finite");
    for (uint32_t y = c.tileY - 1; y < c.tileY + c.tileH + 1u; ++y)
      for (uint32_t x = c.tileX - 1; x < c.tileX + c.tileW + 1u; ++x) {
        const size_t bit = size_t(y) * P + x;
        uint8_t& byte = used[c.page][bit / 8];
        if (byte & (1u << (bit % 8))) {
          problem(name + ": tile overlaps another tile at page " + std::to_string(c.page) + " texel " +
                  std::to_string(x) + "," + std::to_string(y));
          y = c.tileY + c.tileH + 1u;
          break;
        }
        byte |= uint8_t(1u << (bit % 8));
      }
    // Gutters repeat the edge texels.
    bool gutterOk = true;
    for (int j = -1; j <= int(c.tileH) && gutterOk; ++j)
      for (int k = -1; k <= int(c.tileW); ++k) {
        if (j >= 0 && j < int(c.tileH) && k >= 0 && k < int(c.tileW)) continue;
        const int sj = std::clamp(j, 0, int(c.tileH) - 1), sk = std::clamp(k, 0, int(c.tileW) - 1);
        ++r.texelsChecked;
        if (pack.texel(c, k, j) != pack.texel(c, sk, sj) ||
            (pack.hasNormals() && std::memcmp(pack.normalTexel(c, k, j), pack.normalTexel(c, sk, sj), kNormalBytes) != 0)) {
          problem(name + ": gutter texel " + std::to_string(k) + "," + std::to_string(j) + " differs from its edge");
          gutterOk = false;
          break;
        }
      }
  }
  if (points + m.outliersRemoved != m.sourcePoints)
    problem("cells hold " + std::to_string(points) + " points and " + std::to_string(m.outliersRemoved) +
            " were removed as outliers, but META counts " + std::to_string(m.sourcePoints) + " source points");
  return r;
}

}  // namespace sa
