// The GROO section (modes/grooves/groove_cast.h): a model built from given grooves on a packed
// plane round-trips through the pack, and a corrupted section (sizes, block offsets, bin lists,
// piece and profile references) is refused with a message naming the pack, never trusted. On a
// curved surface the rim meets the height field at the capsule's sides. The renderer's gap field
// bounds the distance to the capsules from below everywhere, within a texel.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "../common/render_util.h"
#include "modes/grooves/groove_cast.h"

namespace sa {
namespace {

struct Fixture {
  test::TempDir dir;
  PackReader pack;
  gcast::Model model;
  ExtraSection section;
};

// A flat 1 x 1 plane of points (z = 0, spacing 0.01) and two crossing V grooves 0.05 wide.
void makePlane(Fixture& f) {
  std::vector<Eigen::Vector3d> pts, nrm;
  for (int j = 0; j <= 100; ++j)
    for (int i = 0; i <= 100; ++i) {
      pts.emplace_back(0.01 * i, 0.01 * j, 0);
      nrm.emplace_back(0, 0, 1);
    }
  ASSERT_TRUE(f.pack.open(test::packPoints(f.dir, pts, nrm, "plane")).isOk());
  GrooveSet set;
  for (int k = 0; k < 2; ++k) {
    Groove g;
    g.line = {k ? Eigen::Vector3d(0.2, 0.5, 0) : Eigen::Vector3d(0.5, 0.2, 0), k ? Eigen::Vector3d(0.8, 0.5, 0) : Eigen::Vector3d(0.5, 0.8, 0)};
    g.width = 0.05;
    g.depth = 0.02;
    g.shape = "V";
    set.grooves.push_back(g);
  }
  Groove gap;
  gap.line = {Eigen::Vector3d(0.1, 0.1, 0), Eigen::Vector3d(0.2, 0.1, 0)};
  gap.width = 0.03;
  gap.shape = "gap";
  set.grooves.push_back(gap);
  f.model = gcast::buildModel(f.pack, set);
  f.section = gcast::makeSection(f.pack, f.model, groovesJsonText(set), 0.5);
}

// Writes the pack with `bytes` as its GROO section and reads the section back.
Result<gcast::SectionView> readWith(Fixture& f, const std::vector<uint8_t>& bytes, PackReader& out) {
  ExtraSection s = f.section;
  s.bytes = bytes;
  const std::string path = f.dir.file("with.hfa");
  Status st = rewritePackWithSections(f.pack, path, {s});
  if (!st) return st;
  st = out.open(path);
  if (!st) return st;
  return gcast::readSection(out);
}

TEST(GrooveSection, RoundTripsThroughThePack) {
  Fixture f;
  makePlane(f);
  ASSERT_EQ(f.model.grooves, 2u);  // the gap (depth unknown) is not stored
  EXPECT_EQ(f.model.drawn, 2u);
  EXPECT_EQ(f.model.skipped, 1u);
  ASSERT_FALSE(f.model.cells.empty());
  PackReader p;
  auto v = readWith(f, f.section.bytes, p);
  ASSERT_TRUE(v.isOk()) << v.status().message();
  ASSERT_TRUE(v->present);
  const gcast::Model m = gcast::modelFromSection(p, *v);
  ASSERT_EQ(m.cells.size(), f.model.cells.size());
  for (size_t i = 0; i < m.cells.size(); ++i) {
    ASSERT_EQ(m.cells[i].pieces.size(), f.model.cells[i].pieces.size());
    EXPECT_EQ(m.cells[i].bins, f.model.cells[i].bins);
    for (size_t k = 0; k < m.cells[i].pieces.size(); ++k) {
      const gcast::Piece &a = m.cells[i].pieces[k], &b = f.model.cells[i].pieces[k];
      EXPECT_NEAR(a.halfWidth, b.halfWidth, 1e-6);
      EXPECT_NEAR(a.rimQ[0][0], b.rimQ[0][0], 1e-5);
      EXPECT_NEAR(a.rimQ[1][1], b.rimQ[1][1], 1e-5);
      EXPECT_EQ(a.groove, b.groove);
    }
  }
  EXPECT_NE(v->json.find("\"polyline\""), std::string::npos);
  // Every cell's floor reaches the grooves' depth below the plane.
  for (const auto& c : m.cells) EXPECT_LE(c.floor, -0.019);
}

TEST(GrooveSection, CorruptionIsRefused) {
  Fixture f;
  makePlane(f);
  const std::vector<uint8_t>& good = f.section.bytes;
  gcast::SectionHeader h;
  std::memcpy(&h, good.data(), sizeof(h));
  const size_t entries = sizeof(h), words = entries + size_t(h.cellCount) * 4;
  uint32_t blk = gcast::kNoEntry;
  for (uint32_t i = 0; i < h.cellCount && blk == gcast::kNoEntry; ++i) std::memcpy(&blk, &good[entries + 4 * i], 4);
  ASSERT_NE(blk, gcast::kNoEntry);
  auto word = [&](std::vector<uint8_t>& b, size_t w, uint32_t v) { std::memcpy(&b[words + 4 * w], &v, 4); };
  uint32_t listOff, pieceOff;
  std::memcpy(&listOff, &good[words + 4 * (blk + 2)], 4);
  std::memcpy(&pieceOff, &good[words + 4 * (blk + 3)], 4);
  struct Case {
    const char* what;
    std::vector<uint8_t> bytes;
  };
  std::vector<Case> cases;
  cases.push_back({"truncated", std::vector<uint8_t>(good.begin(), good.begin() + 40)});
  cases.push_back({"short by a word", std::vector<uint8_t>(good.begin(), good.end() - 4)});
  std::vector<uint8_t> b = good;
  b[0] = 9;
  cases.push_back({"version", b});
  b = good;
  std::memcpy(&b[entries], "\xff\xff\xff\x7f", 4);  // the first cell's block
  cases.push_back({"block past the words", b});
  b = good;
  word(b, blk, 0);  // a zero grid
  cases.push_back({"zero grid", b});
  // The sparse bins: the mask, the held bins before each mask word, each held bin's start.
  uint32_t grid;
  std::memcpy(&grid, &good[words + 4 * blk], 4);
  const uint32_t M = gcast::binMaskWords(grid), startsAt = blk + gcast::kBlockHeaderWords + 2 * M;
  const uint32_t held = listOff - gcast::kBlockHeaderWords - 2 * M - 1;
  ASSERT_GT(held, 0u);
  b = good;
  word(b, startsAt + held, 0xfffffff0u);  // the lists' end
  cases.push_back({"bin list past the block", b});
  b = good;
  word(b, startsAt + held - 1, 0xfffffff0u);  // the last held bin's start, past its end
  cases.push_back({"bin list ends before it starts", b});
  b = good;
  for (uint32_t w = 0; w < M; ++w) {  // one held bin fewer in the mask than its counts say
    uint32_t m;
    std::memcpy(&m, &b[words + 4 * (blk + gcast::kBlockHeaderWords + w)], 4);
    if (m == 0) continue;
    word(b, blk + gcast::kBlockHeaderWords + w, m & (m - 1));
    break;
  }
  cases.push_back({"mask and counts disagree", b});
  b = good;
  h.jsonRawBytes = 0xffffffffu;  // a huge groove list stated: refused before it is allocated
  std::memcpy(b.data(), &h, sizeof(h));
  cases.push_back({"huge JSON size", b});
  b = good;
  std::memcpy(&h, good.data(), sizeof(h));
  ASSERT_GT(h.jsonRawBytes, 0u) << "the JSON is stored compressed";
  h.jsonRawBytes -= 1;
  std::memcpy(b.data(), &h, sizeof(h));
  cases.push_back({"JSON size not the frame's", b});
  b = good;
  word(b, blk + listOff, 0xffffu);  // the first list entry: a piece it lacks
  cases.push_back({"bin names a missing piece", b});
  b = good;
  word(b, blk + pieceOff + 12, 0xfffffff0u);  // the first piece's profile
  cases.push_back({"piece names a missing profile", b});
  for (const Case& c : cases) {
    PackReader p;
    auto v = readWith(f, c.bytes, p);
    if (v.isOk() && v->present) {
      ADD_FAILURE() << c.what << ": accepted";
      continue;
    }
    ASSERT_FALSE(v.isOk()) << c.what;
    EXPECT_NE(v.status().message().find("GROO"), std::string::npos) << c.what << ": " << v.status().message();
  }
}

// A groove along a cylinder of points (radius 0.3, the groove along its axis on top): where the
// carved surface meets the height field at the capsule's sides (r just under the lip, past the
// profile) the rim must be the surface, to a quarter of what the surface's tangent plane at the
// line would be off (lip^2 / 2R; a rim that stood off by that drew a step along every groove on a
// curved surface, as on Igea's lips).
// The two-pass renderer skips the carved cast where the gap field says no capsule is near: the
// field must never exceed the true gap (distance to a piece's segment less its lip, or less its
// half width) anywhere in a texel, and should be within a texel of it (else pixels are deferred
// for nothing); past the cap it reads the cap. Its texels also name the anti-aliasing's two
// candidates, which must be the two pieces nearest the texel's centre.
TEST(GrooveGapField, BoundsTheGapToEveryCapsuleFromBelow) {
  Fixture f;
  makePlane(f);
  ASSERT_FALSE(f.model.cells.empty());
  const std::vector<uint32_t> words = gcast::gapField(f.pack, f.model);
  ASSERT_EQ(words.size() >= f.pack.cells().size(), true);
  std::mt19937 rng(5);
  size_t points = 0, capped = 0, candidates = 0;
  double worstSlack = 0, meanSlack = 0;
  size_t slackPoints = 0;
  for (const gcast::CellPieces& cp : f.model.cells) {
    const CellRecord& c = f.pack.cells()[cp.cell];
    ASSERT_NE(words[cp.cell], gcast::kNoEntry);
    float wide;
    std::memcpy(&wide, &words[words[cp.cell]], 4);
    EXPECT_FLOAT_EQ(wide, float(gcast::widestAcross(cp)));
    const double tu = (c.box[1] - c.box[0]) / c.tileW, tv = (c.box[3] - c.box[2]) / c.tileH, q = gcast::gapQuantum(c);
    std::uniform_real_distribution<double> U(c.box[0], c.box[1]), V(c.box[2], c.box[3]);
    for (int k = 0; k < 20000; ++k) {
      const Eigen::Vector2d p(U(rng), V(rng));
      const int i = std::clamp(int((p.x() - c.box[0]) / tu), 0, c.tileW - 1), j = std::clamp(int((p.y() - c.box[2]) / tv), 0, c.tileH - 1);
      const size_t texel = words[cp.cell] + 1 + gcast::kGapFieldWords * (size_t(j) * c.tileW + i);
      const uint32_t w = words[texel];
      double lip = 1e300, width = 1e300;
      // The anti-aliasing's candidates: the two pieces of least (distance - half width) at the
      // texel's centre (where one is within the cap's reach).
      const Eigen::Vector2d ctr(c.box[0] + (i + 0.5) * tu, c.box[2] + (j + 0.5) * tv);
      std::vector<std::pair<double, uint32_t>> byWidth;
      for (uint32_t pi = 0; pi < cp.pieces.size(); ++pi) {
        const gcast::Piece& pc = cp.pieces[pi];
        double s, x;
        const double d = gcast::pieceDistance(pc, p, s, x);
        lip = std::min(lip, d - pc.lip);
        width = std::min(width, d - pc.halfWidth);
        byWidth.emplace_back(gcast::pieceDistance(pc, ctr, s, x) - pc.halfWidth, pi);
        if (d < 2 * pc.lip) {  // how wide the piece looks across where the anti-aliasing can see it
          Eigen::Vector2d g;
          gcast::pieceDistance(pc, p, s, x);
          gcast::pieceRim(pc, s, x, &g);
          const double slope = g.dot(Eigen::Vector2d(-pc.e.y(), pc.e.x()));
          ASSERT_LE(2 * pc.halfWidth * std::sqrt(1 + slope * slope), wide);
        }
      }
      std::sort(byWidth.begin(), byWidth.end());
      if (byWidth[0].first < 65535 * q) {
        ASSERT_EQ(words[texel + 1], byWidth[0].second) << "at " << ctr.transpose();
        if (byWidth.size() > 1 && byWidth[1].first < 65535 * q) {
          ASSERT_EQ(words[texel + 2], byWidth[1].second);
        }
      }
      candidates += words[texel + 1] != gcast::kNoEntry;
      // The shader's bounds at p: the centre's, less p's distance from the centre.
      const double off = (p - ctr).norm(), bLip = (w & 0xffff) * q - off, bWidth = (w >> 16) * q - off;
      ASSERT_LE(bLip, std::max(lip, 0.0) + 1e-12) << "at " << p.transpose();
      ASSERT_LE(bWidth, std::max(width, 0.0) + 1e-12) << "at " << p.transpose();
      if (lip > 0 && (w & 0xffff) != 0xffff) {
        meanSlack += (lip - bLip) / std::min(tu, tv);
        ++slackPoints;
      }
      ++points;
      if ((w & 0xffff) == 0xffff) {
        ++capped;
        EXPECT_GE(lip, 65535 * q - std::hypot(tu, tv));
      } else if (lip > 0) {
        worstSlack = std::max(worstSlack, (lip - bLip) / std::min(tu, tv));
      }
    }
  }
  meanSlack /= double(std::max<size_t>(slackPoints, 1));
  std::printf("[groove-gap] %zu points in %zu cells: %zu past the cap, %zu with a nearest piece; the bound at most %.2f texels under the gap, "
              "%.2f on average\n", points, f.model.cells.size(), capped, candidates, worstSlack, meanSlack);
  EXPECT_GT(capped, 0u);
  EXPECT_GT(candidates, points / 4);
  EXPECT_LE(worstSlack, 1.5);
  EXPECT_LE(meanSlack, 0.5);  // bounds over the texel's square were 0.7 texels under on average
}

TEST(GrooveRim, MeetsACurvedSurfaceAtTheCapsulesSides) {
  test::TempDir dir;
  const double R = 0.3, sp = 0.005;
  std::vector<Eigen::Vector3d> pts, nrm;
  for (int j = -60; j <= 60; ++j)
    for (int i = 0; i <= 120; ++i) {
      const double a = j * sp / R;
      pts.emplace_back(i * sp, R * std::sin(a), R * std::cos(a));
      nrm.emplace_back(0, std::sin(a), std::cos(a));
    }
  PackReader pack;
  ASSERT_TRUE(pack.open(test::packPoints(dir, pts, nrm, "cylinder")).isOk());
  GrooveSet set;
  Groove g;
  g.line = {Eigen::Vector3d(0.1, 0, R), Eigen::Vector3d(0.35, 0, R), Eigen::Vector3d(0.5, 0, R)};
  g.width = 0.04;
  g.depth = 0.015;
  g.shape = "V";
  set.grooves.push_back(g);
  const gcast::Model m = gcast::buildModel(pack, set);
  ASSERT_EQ(m.drawn, 1u);
  const Eigen::Vector3d origin(pack.meta().origin);
  double worst = 0, tangentOff = 0;
  int checked = 0;
  for (const gcast::CellPieces& cp : m.cells) {
    const CellRecord& c = pack.cells()[cp.cell];
    const gcast::HeightField h{&pack, &c};
    for (const gcast::Piece& p : cp.pieces) {
      tangentOff = p.lip * p.lip / (2 * R);
      for (double side : {-0.99, 0.99}) {
        const Eigen::Vector2d q = p.a + p.e * (0.5 * p.length) + Eigen::Vector2d(-p.e.y(), p.e.x()) * (side * p.lip);
        const double hq = h(q.x(), q.y());
        if (std::isnan(hq)) continue;
        worst = std::max(worst, std::abs(gcast::pieceFloor(m, h, p, q) - hq));
        ++checked;
      }
    }
  }
  std::printf("[groove-rim] %d capsule-side points: rim vs height field at most %.2e (a tangent plane at the line: %.2e)\n", checked,
              worst, tangentOff);
  ASSERT_GE(checked, 20);
  EXPECT_LE(worst, 0.25 * tangentOff);
}

}  // namespace
}  // namespace sa
