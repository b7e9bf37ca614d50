// Groove detection on generated scans with known grooves (issue 12's detection acceptance):
// recall of the length with the centre line within half a spacing, widths, depths, false
// grooves on a groove-free plane, uncovered cracks, and the JSON file round trip.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "grooves/grooves.h"

namespace sa {
namespace {

constexpr double kSize = 400, kSpacing = 1, kNoise = 0.1;

// Detected lines in the scan's plane coordinates.
std::vector<std::vector<Eigen::Vector2d>> inPlane(const SyntheticScan& scan, const GrooveSet& set) {
  std::vector<std::vector<Eigen::Vector2d>> out;
  for (const Groove& g : set.grooves) {
    std::vector<Eigen::Vector2d> l;
    for (const Eigen::Vector3d& p : g.line) l.push_back((scan.frame.transpose() * (p - scan.origin)).head<2>());
    out.push_back(l);
  }
  return out;
}

double distToLine(const Eigen::Vector2d& p, const std::vector<Eigen::Vector2d>& l) {
  double best = 1e300;
  for (size_t k = 0; k + 1 < l.size(); ++k) {
    const Eigen::Vector2d ab = l[k + 1] - l[k];
    const double t = ab.squaredNorm() > 0 ? std::clamp((p - l[k]).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 0;
    best = std::min(best, (l[k] + t * ab - p).norm());
  }
  return best;
}

std::vector<Eigen::Vector2d> samples(const std::vector<Eigen::Vector2d>& l, double step) {
  std::vector<Eigen::Vector2d> out;
  for (size_t k = 0; k + 1 < l.size(); ++k) {
    const int n = std::max(1, int(std::ceil((l[k + 1] - l[k]).norm() / step)));
    for (int t = 0; t < n; ++t) out.push_back(l[k] + (l[k + 1] - l[k]) * (double(t) / n));
  }
  out.push_back(l.back());
  return out;
}

bool required(const SyntheticGroove& g) { return g.width >= 3 * kSpacing - 1e-9 && g.depth >= 5 * kNoise - 1e-9; }

struct Scored {
  double trueLength = 0, recalled = 0;     // required grooves
  double falseLength = 0, allTrue = 0;     // detected length near no groove; every groove's length
};

Scored score(const SyntheticScan& scan, const GrooveSet& set, bool print) {
  Scored sc;
  const auto det = inPlane(scan, set);
  for (size_t gi = 0; gi < scan.grooves.size(); ++gi) {
    const SyntheticGroove& g = scan.grooves[gi];
    size_t hit = 0;
    const auto ss = samples(g.line, 0.5 * kSpacing);
    for (const Eigen::Vector2d& p : ss) {
      double best = 1e300;
      for (const auto& l : det) best = std::min(best, distToLine(p, l));
      hit += best <= 0.5 * kSpacing;
    }
    const double len = 0.5 * kSpacing * double(ss.size() - 1);
    sc.allTrue += len;
    if (required(g)) {
      sc.trueLength += len;
      sc.recalled += len * double(hit) / double(ss.size());
    }
    if (print)
      std::printf("  groove %zu: %s w %.1f s d %.1f sigma, %5.1f %% recalled%s\n", gi, g.rounded ? "U" : "V",
                  g.width / kSpacing, g.depth / kNoise, 100.0 * double(hit) / double(ss.size()),
                  required(g) ? "" : " (below the test's bounds)");
  }
  for (const auto& l : det) {
    for (const Eigen::Vector2d& p : samples(l, 0.5 * kSpacing)) {
      bool near = false;
      for (const SyntheticGroove& g : scan.grooves) near = near || distToLine(p, g.line) <= g.width / 2 + kSpacing;
      if (!near) sc.falseLength += 0.5 * kSpacing;
    }
  }
  return sc;
}

// Width and depth of the detections matched to each groove (length-weighted over the pieces
// whose samples lie mostly on it).
struct Measured {
  double width = 0, depth = 0, length = 0;
};

std::vector<Measured> measure(const SyntheticScan& scan, const GrooveSet& set) {
  std::vector<Measured> m(scan.grooves.size());
  const auto det = inPlane(scan, set);
  for (size_t di = 0; di < det.size(); ++di) {
    std::vector<size_t> votes(scan.grooves.size(), 0);
    const auto ss = samples(det[di], 0.5 * kSpacing);
    for (const Eigen::Vector2d& p : ss)
      for (size_t gi = 0; gi < scan.grooves.size(); ++gi)
        votes[gi] += distToLine(p, scan.grooves[gi].line) <= scan.grooves[gi].width / 2 + kSpacing;
    const size_t best = size_t(std::max_element(votes.begin(), votes.end()) - votes.begin());
    if (votes[best] * 2 < ss.size()) continue;
    const Groove& g = set.grooves[di];
    m[best].width += g.width * g.length;
    m[best].depth += g.depth * g.length;
    m[best].length += g.length;
  }
  for (Measured& x : m)
    if (x.length > 0) x.width /= x.length, x.depth /= x.length;
  return m;
}

// The acceptance scene at a spacing and noise: recall >= 90 % of the length (centre line within
// half a spacing) for grooves >= 3 spacings wide and >= 5 noise deep, false length < 2 %, widths
// within a spacing, depths within 2 noise + 10 %.
void checkScene(double unit, double noiseUnits, uint32_t seed) {
  const double s = kSpacing * unit, sigma = kNoise * noiseUnits * unit;
  const SyntheticScan scan = makeGrooveScan(kSize * unit, s, sigma, acceptanceGrooves(kSize * unit, s, sigma), seed);
  const GrooveSet set = detectGrooves(scan.pos.data(), scan.pos.size() / 3, GrooveOptions{});
  std::printf("%zu points, spacing %.4g (measured %.4g), noise %.4g (measured %.4g): %zu grooves over %u regions\n",
              scan.pos.size() / 3, s, set.spacing, sigma, set.noise, set.grooves.size(), set.regions);
  EXPECT_NEAR(set.spacing, s, 0.1 * s);
  EXPECT_NEAR(set.noise, sigma, 0.2 * sigma);
  // Score in spacing units.
  SyntheticScan unitScan = scan;
  GrooveSet unitSet = set;
  for (SyntheticGroove& g : unitScan.grooves) {
    for (Eigen::Vector2d& p : g.line) p /= unit;
    g.width /= unit;
    g.depth /= unit * noiseUnits;
  }
  unitScan.origin /= unit;
  for (Groove& g : unitSet.grooves) {
    for (Eigen::Vector3d& p : g.line) p /= unit;
    g.width /= unit;
    g.depth /= unit * noiseUnits;
    g.length /= unit;
  }
  const Scored sc = score(unitScan, unitSet, true);
  std::printf("recalled %.1f of %.1f spacings (%.1f %%), false %.1f (%.2f %% of all grooves' length)\n", sc.recalled,
              sc.trueLength, 100 * sc.recalled / sc.trueLength, sc.falseLength, 100 * sc.falseLength / sc.allTrue);
  EXPECT_GE(sc.recalled, 0.9 * sc.trueLength);
  EXPECT_LT(sc.falseLength, 0.02 * sc.allTrue);
  const std::vector<Measured> m = measure(unitScan, unitSet);
  for (size_t gi = 0; gi < unitScan.grooves.size(); ++gi) {
    const SyntheticGroove& g = unitScan.grooves[gi];
    if (!required(g)) continue;
    std::printf("  groove %zu: width %.2f (true %.2f) spacings, depth %.2f (true %.2f) noise\n", gi, m[gi].width, g.width,
                m[gi].depth / kNoise, g.depth / kNoise);
    ASSERT_GT(m[gi].length, 0) << "groove " << gi;
    EXPECT_LE(std::fabs(m[gi].width - g.width), kSpacing) << "groove " << gi;
    EXPECT_LE(std::fabs(m[gi].depth - g.depth), 2 * kNoise + 0.1 * g.depth) << "groove " << gi;
  }
}

TEST(Grooves, AcceptanceGroovesAtUnitSpacing) { checkScene(1, 1, 7); }

// Millimetre units, a different seed and relatively less noise: nothing is tuned to one scale.
TEST(Grooves, AcceptanceGroovesAtMillimetreSpacing) { checkScene(0.002, 0.7, 11); }

// False grooves on groove-free noisy planes: under 2 % of the acceptance grooves' length.
TEST(Grooves, NoGroovesOnANoisyPlane) {
  const double trueLength = [] {
    const SyntheticScan scan = makeGrooveScan(kSize, kSpacing, kNoise, acceptanceGrooves(kSize, kSpacing, kNoise), 1);
    return score(scan, GrooveSet{}, false).allTrue;
  }();
  for (uint32_t seed : {3u, 4u, 5u}) {
    const SyntheticScan scan = makeGrooveScan(kSize, kSpacing, kNoise * (1 + seed % 2), {}, seed);
    const GrooveSet set = detectGrooves(scan.pos.data(), scan.pos.size() / 3, GrooveOptions{});
    std::printf("seed %u: %zu false grooves, %.1f spacings long\n", seed, set.grooves.size(), set.totalLength());
    EXPECT_LT(set.totalLength(), 0.02 * trueLength);
  }
}

// A deep crack returns no points: found as an uncovered strip ("gap"), depth unknown.
TEST(Grooves, UncoveredCracksAreGaps) {
  std::vector<SyntheticGroove> cracks(2);
  cracks[0].line = {Eigen::Vector2d(40, 60), Eigen::Vector2d(150, 110)};
  cracks[0].width = 2.5;
  cracks[1].line = {Eigen::Vector2d(60, 170), Eigen::Vector2d(170, 150)};
  cracks[1].width = 5;
  for (SyntheticGroove& c : cracks) c.depth = 50, c.uncovered = true;
  const SyntheticScan scan = makeGrooveScan(200, kSpacing, kNoise, cracks, 5);
  const GrooveSet set = detectGrooves(scan.pos.data(), scan.pos.size() / 3, GrooveOptions{});
  const std::vector<Measured> m = measure(scan, set);
  for (const Groove& g : set.grooves) {
    std::printf("  %s width %.2f length %.1f\n", g.shape.c_str(), g.width, g.length);
    EXPECT_EQ(g.shape, "gap");
  }
  const Scored sc = score(scan, set, true);
  for (size_t i = 0; i < cracks.size(); ++i) {
    EXPECT_GE(m[i].length, 0.8 * (cracks[i].line[1] - cracks[i].line[0]).norm()) << "crack " << i;
    EXPECT_LE(std::fabs(m[i].width - cracks[i].width), kSpacing) << "crack " << i;
  }
  EXPECT_LT(sc.falseLength, 0.02 * sc.allTrue);
}

// Given grooves (here the true centre lines with a placeholder width, as a user would draw
// them) measured in the points: widths and depths as the detector's bounds; a line away from
// every point is kept as given.
TEST(Grooves, MeasuresGivenGrooves) {
  const SyntheticScan scan = makeGrooveScan(kSize, kSpacing, kNoise, acceptanceGrooves(kSize, kSpacing, kNoise), 9);
  GrooveSet given;
  for (const SyntheticGroove& t : scan.grooves) {
    Groove g;
    for (const Eigen::Vector2d& p : t.line) g.line.push_back(scan.toWorld(p));
    g.width = 1;
    g.shape = "given";
    given.grooves.push_back(g);
  }
  Groove away;
  away.line = {scan.toWorld({100, 100}) + 300 * scan.frame.col(2), scan.toWorld({150, 100}) + 300 * scan.frame.col(2)};
  away.width = 2;
  given.grooves.push_back(away);
  const GrooveSet set = measureGrooves(scan.pos.data(), scan.pos.size() / 3, given, GrooveOptions{});
  ASSERT_EQ(set.grooves.size(), given.grooves.size());
  EXPECT_EQ(set.unmeasured, 1u);
  EXPECT_EQ(set.grooves.back().width, 2);
  for (size_t gi = 0; gi < scan.grooves.size(); ++gi) {
    const SyntheticGroove& t = scan.grooves[gi];
    const Groove& g = set.grooves[gi];
    std::printf("  groove %zu: %s width %.2f (true %.2f %s), depth %.2f (true %.2f) noise\n", gi, g.shape.c_str(), g.width,
                t.width, t.rounded ? "U" : "V", g.depth / kNoise, t.depth / kNoise);
    if (!required(t)) continue;
    EXPECT_LE(std::fabs(g.width - t.width), kSpacing) << "groove " << gi;
    EXPECT_LE(std::fabs(g.depth - t.depth), 2 * kNoise + 0.1 * t.depth) << "groove " << gi;
  }
}

TEST(Grooves, JsonRoundTripAndErrors) {
  const std::string dir = testing::TempDir();
  GrooveSet set;
  set.spacing = 0.5;
  set.noise = 0.01;
  Groove g;
  g.line = {Eigen::Vector3d(1, 2, 3), Eigen::Vector3d(4, 6, 3)};
  g.width = 1.25;
  g.depth = 0.5;
  g.length = 5;
  g.confidence = 0.75;
  g.shape = "U";
  g.profile = {{-1.f, 0.f}, {0.f, -0.5f}, {1.f, 0.f}};
  set.grooves.push_back(g);
  const std::string path = dir + "/grooves_roundtrip.json";
  ASSERT_TRUE(writeGroovesJson(set, path).isOk());
  Result<GrooveSet> back = readGroovesJson(path);
  ASSERT_TRUE(back.isOk()) << back.status().message();
  ASSERT_EQ(back->grooves.size(), 1u);
  EXPECT_EQ(back->grooves[0].line, g.line);
  EXPECT_DOUBLE_EQ(back->grooves[0].width, 1.25);
  EXPECT_DOUBLE_EQ(back->grooves[0].depth, 0.5);
  EXPECT_DOUBLE_EQ(back->grooves[0].length, 5);
  EXPECT_EQ(back->grooves[0].shape, "U");
  EXPECT_EQ(back->grooves[0].profile.size(), 3u);
  ASSERT_TRUE(writeGroovesCsv(set, dir + "/grooves_roundtrip.csv").isOk());
  const struct {
    const char* text;
    const char* message;
  } bad[] = {
      {"{\"grooves\": [", "not valid JSON"},
      {"{\"lines\": []}", "\"grooves\" array"},
      {"{\"grooves\": [{\"polyline\": [[0,0,0],[1,0,0]]}]}", "groove 0: missing \"width\""},
      {"{\"grooves\": [{\"width\": 1, \"polyline\": [[0,0,0]]}]}", "at least 2"},
      {"{\"grooves\": [{\"width\": 1, \"polyline\": [[0,0,0],[1,0]]}]}", "point 1 is not [x, y, z]"},
      {"{\"grooves\": [{\"width\": -1, \"polyline\": [[0,0,0],[1,0,0]]}]}", "width must be > 0"},
      {"{\"version\": 9, \"grooves\": []}", "newer"},
  };
  for (const auto& b : bad) {
    const std::string p = dir + "/grooves_bad.json";
    std::ofstream(p) << b.text;
    Result<GrooveSet> r = readGroovesJson(p);
    ASSERT_FALSE(r.isOk()) << b.text;
    EXPECT_NE(r.status().message().find(p), std::string::npos) << r.status().message();
    EXPECT_NE(r.status().message().find(b.message), std::string::npos) << r.status().message();
  }
}

}  // namespace
}  // namespace sa
