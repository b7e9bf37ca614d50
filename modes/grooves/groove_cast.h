// The `grooves` mode's core (MODES.md §4; seed 003 §3-5 and Bosch & Patow's real-time form),
// GL-free: grooves (detected in the raw points or given, grooves/grooves.h) become per-cell
// pieces - one straight piece of a centre line in the cell's frame, a rim fitted across the
// groove to the height field just outside its lips, and the groove's cross-section profile -
// binned in a uniform grid over the cell's tile, and the cast that carves them into the height
// field.
//
// The carved surface: inside a piece's capsule (r < its lip, r the distance to its segment, the
// lip half a width plus a texel, and two sample spacings for points: ends are rounded, joints and crossings
// are the union of the grooves) the lowest floor there, floor_i = rim_i - D_i(r), the rim bridged
// across the groove from the height field at its lips and D the profile (0 past the half width);
// elsewhere the cell's height field h. Across the groove the rim is a parabola fitted to h on both
// sides just outside the lips, so at the capsule's sides it meets h to within the fit's residual
// with its slope and curvature: a curved surface stays whole (a tangent plane at the line would
// stand off a convex lip or a fold by the curvature times the lip squared), and scan noise averages
// out over the fit. The data's own crack in h (blurred by the pack's
// reconstruction, wider and shallower than the profile) is replaced, not deepened. The cast
// (castGrooved): h's first hit tH; a floor above h crossed before tH (each piece near the stretch
// that can reach such floors: its first floor crossing); from tH, through the air of whatever piece the ray is in (to that
// piece's floor or out of its capsule) until solid; out of every capsule and above h, on from
// there. A groove that was neither detected nor given is never drawn: cells without pieces cast
// their height field alone.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "atlas/pack_file.h"
#include "common/error.h"
#include "grooves/grooves.h"

namespace sa::gcast {

// Profile depth samples per groove: D at r = k / (kProfileSamples - 1) half widths, k = 0..8
// (the last is 0: the rim), linear in between.
inline constexpr int kProfileSamples = 9;
inline constexpr int kPieceWords = 14;
inline constexpr int kBlockHeaderWords = 6;  // grid, pieces, lists' word, pieces' word, floor, rise (f32)
inline constexpr int kMaxGrid = 256;
inline constexpr double kMaxPieceTexels = 8;

struct Piece {
  Eigen::Vector2d a = Eigen::Vector2d::Zero(), e = Eigen::Vector2d::UnitX();  // start and unit direction (u, v)
  double length = 0, halfWidth = 0;
  // The rim: at the start (end 0) and the end (end 1) a parabola across, rim = q[0] + q[1] x +
  // q[2] x^2 (x across the line), fitted to the height field on both sides over a band just
  // outside the lips (past the reach of the reconstruction's blur of the crack); along, the
  // coefficients linear between the ends and on past them (the rounded ends).
  double rimQ[2][3] = {{0, 0, 0}, {0, 0, 0}};
  double lip = 0;  // the capsule's radius: half a width, a texel (and two sample spacings for points)
  uint32_t groove = 0;  // its profile
};

struct CellPieces {
  uint32_t cell = 0;
  int grid = 1;                              // grid x grid bins over the cell's (u, v) box
  // The lowest w the carved surface reaches over the cell's box (at most its wMin): the cast
  // runs down to it (the grooves cut below the height field's box).
  double floor = 0;
  // How far a floor rises above the height field anywhere in the cell's capsules (0: nowhere by
  // more than a twentieth of a texel): a ray can cross such a floor before the height field's hit,
  // within rise / |d.w| of it; the cast looks there only where rise > 0.
  double rise = 0;
  std::vector<Piece> pieces;
  std::vector<std::vector<uint32_t>> bins;   // grid * grid lists of piece indices (row-major, u fastest)
};

struct Model {
  std::vector<float> profiles;               // kProfileSamples per groove, frame (world) units
  std::vector<CellPieces> cells;             // only cells with pieces, in cell order
  std::vector<int32_t> cellIndex;            // per pack cell: index into cells, -1 when none
  uint32_t grooves = 0, skipped = 0;         // profiles stored; skipped: gaps, and grooves on no cell's surface
  uint32_t drawn = 0;                        // grooves with pieces in some cell
  const CellPieces* find(uint32_t cell) const {
    return cell < cellIndex.size() && cellIndex[cell] >= 0 ? &cells[size_t(cellIndex[cell])] : nullptr;
  }
};

// The profile of a groove as kProfileSamples depths over r in [0, half width]: its measured
// cross-section (Groove::profile: residuals, negative below the rim) folded over the centre line (both sides averaged), else its shape (V: linear,
// U: a semi-ellipse) from width and depth. Gaps (no points inside, depth unknown) get none.
bool profileOf(const Groove& g, float out[kProfileSamples]);

// Pieces of every groove in every cell whose surface it lies on (the groove's line within its
// depth plus two texels of the cell's height field), at most 8 texels long (so the rim follows
// the surface), their lips from the height field.
Model buildModel(const PackReader& pack, const GrooveSet& set);

// The pack section `GROO` (docs/FORMAT.md): the model and the groove set's JSON (so `view` and
// `info` list the grooves a pack draws).
inline constexpr char kSectionId[4] = {'G', 'R', 'O', 'O'};
// 1 (tangent-plane rims) and 2 (a (first, count) pair for every bin, the JSON uncompressed) are
// refused: bake it again.
inline constexpr uint32_t kSectionVersion = 3;
inline constexpr uint32_t kNoEntry = 0xffffffffu;
inline constexpr int kJsonZstdLevel = 9;
inline constexpr uint64_t kMaxJsonBytesPerGroove = 65536;  // a reader's bound on the JSON's stated size
// A block's bins are sparse: a bit a bin (set: it holds pieces) in this many words, as many words
// of the held bins before each, then each held bin's first list entry and the lists' end.
inline constexpr uint32_t binMaskWords(uint32_t grid) { return (grid * grid + 31) / 32; }
struct SectionHeader {
  uint32_t version, cellCount, grooveCount, pieceCount;
  double bakeSeconds;
  uint64_t wordCount;   // words after the entry table: profiles, then the cells' blocks
  uint64_t jsonBytes;   // the groove set as JSON (zstd; as it is where jsonRawBytes is 0), after the words
  uint32_t profileSamples, jsonRawBytes;
  uint8_t zero[16];
};
static_assert(sizeof(SectionHeader) == 64);

ExtraSection makeSection(const PackReader& pack, const Model& m, const std::string& json, double bakeSeconds);

struct SectionView {
  bool present = false;
  SectionHeader header{};
  const uint32_t* entries = nullptr;  // per cell: its block's first word, kNoEntry when none
  const uint32_t* words = nullptr;
  std::string json;
  uint64_t bytes = 0;
};
Result<SectionView> readSection(const PackReader& pack);
// How far cell i's floors rise above its height field (its block's f32 `rise`; 0 without a block).
float blockRise(const SectionView& v, uint32_t cell);
Model modelFromSection(const PackReader& pack, const SectionView& v);

// The renderer's gap field (two passes, viewer/renderer.cpp): per texel of each cell with pieces,
// lower bounds at the texel's centre of min over its pieces of (distance to the piece's segment
// - its lip) and of (distance - its half width), in frame units (both change by at most the
// distance moved: the shader takes off a point's distance from the centre to bound them there;
// before 2026-12-06 the field held the bounds over the texel's square, up to 0.7 texels lower
// on average): where they exceed the reach of
// every rule that can change a pixel (the capsule and the stretch a floor above h is searched
// over; the anti-aliasing's footprint), the carved cast's answer is the height field's. Clamped to
// kGapFieldTexels texels (a larger reach reads the cap and takes the carved cast). With them, the
// two pieces of least (distance - half width) at the texel's centre: the anti-aliasing's
// candidates (modeFootprintColor), read instead of searching the bins around every pixel. Words: per
// pack cell the first word of its field (kNoEntry: none), then the fields: widestAcross(cell) as
// an f32, then row-major (u fastest) kGapFieldWords words a texel: the lip's bound in the low 16
// bits and the half width's in the high, each in units of gapQuantum(cell), rounded down; the
// nearest piece's index in the cell (kNoEntry: none within the cap's reach); the second nearest's.
inline constexpr double kGapFieldTexels = 32;
inline constexpr size_t kGapFieldWords = 3;
double gapQuantum(const CellRecord& c);
// The most any of the cell's pieces can measure across as seen from any direction (frame units):
// twice its half width over the cosine of the rim's steepest slope across. Where a pixel is wider
// than that the footprint's rays draw every groove there, and the first pass need not defer to
// the carved cast.
double widestAcross(const CellPieces& cp);
std::vector<uint32_t> gapField(const PackReader& pack, const Model& m);

// --- the cast (the shader's grooves.glsl in double) ---

// Distance from (u, v) to the piece's segment; s, x: the point's coordinates along and across.
double pieceDistance(const Piece& p, const Eigen::Vector2d& q, double& s, double& x);
// The profile depth at r (0 at and past the half width); slope: dD/dr.
double profileDepth(const float* profile, double r, double halfWidth, double* slope = nullptr);
// A cell's height field (exact::surfaceHeight: the shader's sampleHeight in double; NaN uncovered).
struct HeightField {
  const PackReader* pack = nullptr;
  const CellRecord* cell = nullptr;
  double operator()(double u, double v) const;
  double texel() const;
};
// The rim at the point (s, x) of the piece's frame; gradient: d rim / d(u, v) (shading).
double pieceRim(const Piece& p, double s, double x, Eigen::Vector2d* gradient = nullptr);
// The profile's slope for shading at r: linear between its facets' centres (the geometry keeps the
// facets; the shading does not show them as bands).
double smoothSlope(const float* profile, double r, double halfWidth);
// floor_i at (u, v): rim - D(r) (D = 0 past the half width: out to the lip the rim replaces the
// data's blurred crack); gradient (shading): d floor / d(u, v) with the smooth slope.
double pieceFloor(const Model& m, const HeightField& h, const Piece& p, const Eigen::Vector2d& q,
                  Eigen::Vector2d* gradient = nullptr);
// Where the ray o + t d, inside piece p's air at t, leaves it: a point on or under its floor
// (f <= 0), or just out of its capsule, at most t1.
double airExit(const Model& m, const HeightField& h, const Piece& p, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
               double t, double t1);
// The first t in [t0, t1] where the ray is on or under piece p's floor inside its capsule (its
// entry if it enters under the floor), -1 when none.
double floorCrossing(const Model& m, const HeightField& h, const Piece& p, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                     double t0, double t1);
// Whether frame point q lies in a capsule of cell cp's pieces; air: a piece whose floor q is above
// (-1: q is solid); lowest: the piece with the lowest floor over q.
bool cover(const Model& m, const HeightField& h, const CellPieces& cp, const Eigen::Vector3d& q, int& air, int& lowest);

struct CastResult {
  double t = 0;
  int piece = -1;  // the piece whose floor was hit (its facet shades), -1: the height field
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // frame, when piece >= 0
  uint32_t iterations = 0;
};
// First point of o + t d over [t0, t1] under the carved surface (cell c, frame coordinates);
// the height field by the exact traversal without pyramid (exact::traceCellLinear).
bool castGrooved(const PackReader& pack, const CellRecord& c, const Model& m, uint32_t cell, const Eigen::Vector3d& o,
                 const Eigen::Vector3d& d, double t0, double t1, CastResult& out);

}  // namespace sa::gcast
