// The `vdm` mode's core (MODES.md §1; Wang et al., "View-Dependent Displacement Mapping", 2003),
// GL-free: the bake, the compressed per-cell function, and the lookup the shader mirrors.
//
// For a texel (x, y) of a cell and a view direction (theta, phi) pointing into the box
// (theta from the inward height axis, -W), d(x, y, theta, phi) is the distance from the texel's
// point on the box top, P = (u, v, wMax), along that direction to the surface (the exact mode's
// first above-to-below crossing; curvature dropped: cells are planes, 001 §3.1), with a hit bit;
// where the ray leaves the box without a hit, d is the exit distance (smooth across the miss
// boundary, 000 §4.1) and the bit is 0. Sampled on kThetas x kPhis directions, in texel units.
//
// Compression (001 §3.3, without the curvature axis): per cell the matrix rows (x, y) x columns
// (theta, phi) is reduced by PCA to its mean plus k eigen-directions (E_k) with per-texel weights
// (W_k); k is the smallest rank whose reconstruction error at the hit samples stays within the
// bake's tolerance (p95), at most kMaxRank. Hit bits are kept exactly.
//
// Lookup (the shader's rule, 001 §3.2 with a verify step): the 16 samples around (x, y, theta,
// phi) (bilinear in the texel, bilinear in the direction): all miss -> miss; all hit -> the
// interpolated d, verified against the height field within +-1.5 texels (false position); mixed,
// or a failed verify -> the exact traversal (a fallback, counted).
#pragma once
#include <cstdint>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "atlas/pack_file.h"
#include "common/error.h"
#include "modes/exact/exact.h"

namespace sa::vdm {

inline constexpr int kThetas = 8;
inline constexpr int kPhis = 32;
inline constexpr int kDirs = kThetas * kPhis;
inline constexpr int kMaxRank = 32;
inline constexpr double kMaxThetaDeg = 87.0;  // the last theta sample; steeper views clamp to it

// Direction sample (i, j): theta_i = kMaxThetaDeg * i / (kThetas - 1), phi_j = 2 pi j / kPhis.
double thetaOf(int i);
double phiOf(int j);
// The inward unit direction of (theta, phi) in the cell frame: (sin t cos p, sin t sin p, -cos t).
Eigen::Vector3d direction(double theta, double phi);

// One cell's baked function.
struct CellFunction {
  uint32_t cell = 0;
  int tileW = 0, tileH = 0, rank = 0;
  double texel = 0;                // texel size used for the units (the smaller of u and v)
  std::vector<float> mean;         // kDirs
  std::vector<float> basis;        // rank x kDirs (row k is E_k)
  std::vector<float> weights;      // texels x rank (W_k per texel, row-major texels)
  std::vector<uint32_t> hitBits;   // texels x kDirs / 32
  double bakeSeconds = 0;
  double rmsError = 0, p95Error = 0;  // reconstruction error at hit samples, texels
  bool hit(int texel, int dir) const { return (hitBits[size_t(texel) * (kDirs / 32) + dir / 32] >> (dir % 32)) & 1u; }
  // The reconstructed d (texels) of a texel in direction sample dir.
  double value(int texel, int dir) const;
  uint64_t bytes() const;  // as stored: fp16 values, hit bits
};

struct BakeOptions {
  double tolerance = 1.0;  // texels: p95 reconstruction error at hits the rank must reach (the verify bracket is 1.5)
  int maxRank = kMaxRank;
};

// Bakes one cell (raw samples by the exact traversal; pyramid = that cell's XMAX codes).
CellFunction bakeCell(const PackReader& pack, uint32_t cell, const uint16_t* pyramid, const BakeOptions& opt = {});

// The raw samples (texels x kDirs, texel units) and hit bits, before compression (tests, the toy).
void sampleCell(const PackReader& pack, uint32_t cell, const uint16_t* pyramid, std::vector<float>& d,
                std::vector<uint8_t>& hit);

struct LookupStats {
  uint64_t lookups = 0, predicted = 0, missedFast = 0, fallbacks = 0;
};

// The shader's lookup for a ray entering cell fn.cell through its top face at frame point
// (u, v, wMax) with unit direction dir (dir.z < 0). Returns hit and the distance along dir (frame
// units); predictOnly: return the interpolated prediction without verify or fallback (tests).
bool lookup(const PackReader& pack, const CellFunction& fn, const uint16_t* pyramid, double u, double v,
            const Eigen::Vector3d& dir, double& t, LookupStats* stats = nullptr, bool predictOnly = false);

// The pack section (docs/FORMAT.md, `VDMF`): the baked cells' functions, fp16 values packed two to
// a 32-bit word, laid out as the shader reads them.
inline constexpr char kSectionId[4] = {'V', 'D', 'M', 'F'};
inline constexpr uint32_t kSectionVersion = 1;
inline constexpr uint32_t kNoEntry = 0xffffffffu;
struct SectionHeader {
  uint32_t version;
  uint32_t cellCount;   // the pack's
  uint32_t bakedCells;
  uint32_t thetas, phis;
  float maxThetaDeg;
  double bakeSeconds;
  uint64_t wordCount;   // data words after the entry table
  double tolerance;     // the bake's rank tolerance, texels
  uint64_t budget;      // the byte budget it was baked under (0: none)
  uint8_t zero[8];
};
static_assert(sizeof(SectionHeader) == 64);
// Words of a cell's block header: rank, tileW | tileH << 16, then offsets (words from the block's
// start) of the mean, basis, weights and hit bits, the texel size (float bits), zero.
inline constexpr int kBlockHeaderWords = 8;

// Which cells to bake: those whose box meets the clip box (world coordinates; all when not set),
// in cell order, while the section stays within the byte budget (0: no budget).
struct Selection {
  bool clip = false;
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();
  uint64_t budget = 0;
};

struct BakeReport {
  uint32_t candidates = 0, baked = 0, overBudget = 0;
  uint64_t texels = 0, bytes = 0;
  double seconds = 0, meanRank = 0;
};

// Bakes the selected cells on every core; progress(done, total) is called as cells finish.
ExtraSection bakeSection(const PackReader& pack, const Selection& sel, const BakeOptions& opt, BakeReport& report,
                         const std::function<void(uint64_t, uint64_t)>& progress = nullptr);

struct SectionView {
  bool present = false;
  SectionHeader header{};
  const uint32_t* entries = nullptr;  // cellCount, kNoEntry where not baked
  const uint32_t* words = nullptr;
  uint64_t bytes = 0;
};
Result<SectionView> readSection(const PackReader& pack);

// A baked cell's function back from the section (tests compare it with bakeCell's).
CellFunction cellFromSection(const SectionView& v, uint32_t cell);

}  // namespace sa::vdm
