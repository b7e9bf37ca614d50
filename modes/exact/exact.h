// The `exact` mode's core (MODES.md §5; Tevs, Ihrke & Seidel, "Maximum Mipmaps for Fast,
// Accurate, and Scalable Dynamic Height Field Rendering", I3D 2008), in double precision. GL-free:
// the bake writes these pyramids into the pack, the CPU reference (CpuRaycaster) traces them,
// and exact.glsl is the same traversal in float.
//
// The surface is the one every mode renders (heightfield.glsl, sampleHeight): between four texel
// centres a bilinear patch; where one of the four is uncovered the nearest texel decides
// coverage and the uncovered corners take its tangent plane, so such a patch splits into four
// quadrant pieces, each a bilinear function of its own. A hit is the first crossing from above to
// below inside the covered region; entering it below the surface is the sheet's side, not a hit.
//
// The pyramid: level 0 has one node per patch ((W+1) x (H+1), the gutter ring included); a
// node holds the largest height any covered piece of its patch reaches, as a 16-bit height code
// rounded up (0: nothing covered; 65535: unbounded, never skipped), and the smallest, rounded
// down (0: unbounded below; 65535 where nothing is covered); each level above is the 2x2
// maximum and minimum of the one below (odd sizes round up), up to a single node. The maxima
// skip a ray passing above the surface; the minima skip one passing below it (a ray looking
// at the sheet's underside, or under it through a hole), which would otherwise solve every
// patch it crosses.
#pragma once
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "atlas/pack_file.h"

namespace sa::exact {

inline constexpr uint16_t kNodeEmpty = 0;        // nothing covered under the node
inline constexpr uint16_t kNodeUnbounded = 65535;  // may reach the box top: always descend
inline constexpr uint16_t kNodeNoFloor = 65535;    // a minimum over nothing covered (empty node)
// The traversal's safety cap for a W x H tile (a ray that reaches it is counted and misses): a
// ray crossing every patch of the tile at level 0, with an ascent and descent at each, stays
// below it, so only a traversal that stopped advancing reaches it.
inline uint32_t maxNodeVisits(int tileW, int tileH) { return 4u * uint32_t(tileW + tileH + 2) + 64u; }

// Node counts of every level of a tile's pyramid (level 0 first).
struct Levels {
  int count = 0;
  int w[17] = {}, h[17] = {};
  uint64_t offset[17] = {};  // first node of each level in the tile's code array
  uint64_t total = 0;
};
Levels levelsOf(int tileW, int tileH);

// Appends cell c's pyramid to out: levelsOf(c.tileW, c.tileH).total nodes, two codes each
// (maximum, minimum), level 0 first, row-major.
void buildCellPyramid(const PackReader& pack, const CellRecord& c, std::vector<uint16_t>& out);

// Every cell's pyramid, concatenated in cell order; offsets[i] is cell i's first code (even).
struct Pyramids {
  std::vector<uint64_t> offsets;
  std::vector<uint16_t> codes;
  uint64_t bytes() const { return offsets.size() * 8 + codes.size() * 2; }
};
Pyramids buildPyramids(const PackReader& pack);

// The pack section that stores them (docs/FORMAT.md, `XMAX`).
inline constexpr char kSectionId[4] = {'X', 'M', 'A', 'X'};
inline constexpr uint32_t kSectionVersion = 2;  // 1: maxima only
struct SectionHeader {
  uint32_t version;
  uint32_t cellCount;
  uint64_t codeCount;
  double bakeSeconds;
  uint64_t zero;
};
static_assert(sizeof(SectionHeader) == 32);

// Builds every cell's pyramid and lays it out as the XMAX section; seconds: the bake's time.
ExtraSection bakeSection(const PackReader& pack, double* seconds = nullptr);

// A pack's XMAX section, checked (sizes, offsets inside, one pyramid per cell); present = false
// when the pack has none.
struct SectionView {
  bool present = false;
  double bakeSeconds = 0;
  const uint64_t* offsets = nullptr;
  const uint16_t* codes = nullptr;
  uint64_t codeCount = 0;
  uint64_t bytes = 0;
};
Result<SectionView> readSection(const PackReader& pack);

struct TraceStats {
  uint32_t nodeVisits = 0;   // pyramid nodes looked at (level-0 patches included)
  uint32_t pieces = 0;       // patch pieces solved exactly
  bool capped = false;       // stopped at maxNodeVisits
};

// First hit of o + t d (frame coordinates of cell c, d unit or not) over [t0, t1] under the
// surface rule above, using the cell's pyramid (codes = its first code, as buildCellPyramid
// lays it out). Returns false on a miss.
bool traceCell(const PackReader& pack, const CellRecord& c, const uint16_t* codes, const Eigen::Vector3d& o,
               const Eigen::Vector3d& d, double t0, double t1, double& tHit, TraceStats* stats = nullptr);

// The rendered surface's height at frame point (u, v) of cell c (the shader's sampleHeight, in
// double), NaN where uncovered.
double surfaceHeight(const PackReader& pack, const CellRecord& c, double u, double v);

// The same answer without the pyramid: every patch along the ray, in order (tests check the
// pyramid against it).
bool traceCellLinear(const PackReader& pack, const CellRecord& c, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                     double t0, double t1, double& tHit);

}  // namespace sa::exact
