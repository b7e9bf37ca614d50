// Grooves (MODES.md §4): cracks and joints found in raw scan points, as measurable polylines.
// Seed 003 assumes grooves are given; here they are detected: per region a planar frame, the
// residual against a robust low-pass, Hessian valleys at the crack's scale with a threshold from
// the measured noise, sub-texel centre lines (Steger), hysteresis linking, a profile fitted to
// the raw points across each line, and thin elongated uncovered strips (deep cracks return no
// points). Regions are merged in world coordinates. Plain data in, plain data out; no GL.
#pragma once
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "common/error.h"

namespace sa {

struct Groove {
  std::vector<Eigen::Vector3d> line;  // centre line on the surface (the rim level), world units
  double width = 0;                   // opening at the rim, world units (uncertainty: GrooveSet::spacing)
  double depth = 0;                   // below the rim; 0 for an uncovered strip (no points: unknown)
  double length = 0;                  // along the line
  double confidence = 0;              // 0..1: the valley's strength over the noise
  std::string shape = "V";            // "V", "U" (rounded), "gap" (uncovered strip), "given"
  // Median cross-section: (offset across, height below the rim) pairs, world units.
  std::vector<std::pair<float, float>> profile;
};

struct GrooveSet {
  double spacing = 0;  // sample spacing of the points (the widths' uncertainty)
  double noise = 0;    // measured noise (robust std of the residual), world units
  uint32_t regions = 0, skippedRegions = 0;  // skipped: not a height field in any frame
  uint32_t unmeasured = 0;  // measureGrooves: given grooves with too few points beside them (kept as given)
  std::vector<Groove> grooves;
  double totalLength() const;
};

struct GrooveOptions {
  double spacing = 0;        // 0: estimated from the points
  double minWidth = 1.5;     // in spacings: the narrowest groove looked for
  double maxWidth = 8;       // in spacings: the widest
  double minLength = 6;      // in spacings: shorter lines are dropped
  double minDepth = 0.1;     // in spacings: shallower ones too (and any under twice the noise)
  double threshold = 5;      // valley strength over the noise that starts a line
  double lowThreshold = 3;   // ... that continues one (hysteresis)
  double region = 64;        // in spacings: the side of a detection region (each gets a margin)
  bool gaps = true;          // thin elongated uncovered strips are grooves too
  // The side grooves open to (a groove seen from behind is a ridge). Zero: from the data: a
  // nearly planar scene (terrain, a wall) takes the side its residual leans to, anything else
  // the side away from its centroid (statues, parts).
  Eigen::Vector3d outside = Eigen::Vector3d::Zero();
  std::function<void(uint64_t done, uint64_t total)> progress;  // regions
};

// pos: n xyz-interleaved positions, world units.
GrooveSet detectGrooves(const double* pos, size_t n, const GrooveOptions& opt);

// Given grooves (a user's, edited or hand-drawn: GrooveSet::grooves' lines) measured in the
// points: per piece of --region spacings a PCA plane, the robust low-pass, a V or U profile
// fitted to the points across the line; the line is lifted to the rim. Grooves with too few
// points beside them are kept as given (GrooveSet::unmeasured).
GrooveSet measureGrooves(const double* pos, size_t n, const GrooveSet& given, const GrooveOptions& opt);

// Export / import (grooves_io.cpp). JSON holds everything; CSV one row per groove with the
// polyline as a ';'-separated list of x y z triples.
Status writeGroovesJson(const GrooveSet& set, const std::string& path);
Status writeGroovesCsv(const GrooveSet& set, const std::string& path);
Result<GrooveSet> readGroovesJson(const std::string& path);
// The same JSON as text, and parsed from text (path: names the source in errors).
std::string groovesJsonText(const GrooveSet& set);
Result<GrooveSet> parseGroovesJson(const std::string& text, const std::string& path);

// Synthetic test scans (synthetic.cpp): a tilted, gently undulating plane sampled on a jittered
// grid of spacing `spacing` with Gaussian height noise `noise`, and grooves carved into it.
struct SyntheticGroove {
  std::vector<Eigen::Vector2d> line;  // plane coordinates
  double width = 0, depth = 0;
  bool rounded = false;               // U (semi-ellipse) instead of V
  bool uncovered = false;             // points inside are removed (a deep crack)
};
struct SyntheticScan {
  std::vector<double> pos;             // xyz-interleaved
  std::vector<SyntheticGroove> grooves;
  Eigen::Matrix3d frame;               // columns: plane u, v, normal (world)
  Eigen::Vector3d origin;
  double spacing = 0, noise = 0, size = 0;
  Eigen::Vector3d toWorld(const Eigen::Vector2d& p) const;  // on the plane at height 0 of the undulation-free base
  double baseHeight(const Eigen::Vector2d& p) const;        // the undulation
};
// The ten grooves of the acceptance test (straight, curved, crossing, ending; V and U;
// 1.5-6 spacings wide, 3-20 noise deep), laid out on a size x size plane.
std::vector<SyntheticGroove> acceptanceGrooves(double size, double spacing, double noise);
// A size x size plane with `grooves` (plane coordinates, world widths and depths) carved in.
SyntheticScan makeGrooveScan(double size, double spacing, double noise, const std::vector<SyntheticGroove>& grooves,
                             uint32_t seed);

}  // namespace sa
