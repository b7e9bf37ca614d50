// Streamed packs: tiles decoded on background threads in the order the view asks for them, and
// a streamed window's image, once every tile is resident, the same as a pack uploaded whole.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "../common/pack_damage.h"
#include "../common/render_util.h"
#include "preprocess/pipeline.h"
#include "viewer/eval.h"
#include "viewer/renderer.h"
#include "viewer/tile_cache.h"
#include "viewer/tile_streamer.h"

namespace sa {
namespace {

// A real scan with compressed pages: the autzen LAS (2700-odd cells).
std::string packAutzen(const test::TempDir& d) {
  EXPECT_TRUE(test::haveSharedData()) << "../shared/data is missing";
  auto in = InputSet::open({test::sharedData("lidar/autzen_trim.las")});
  EXPECT_TRUE(in.isOk());
  PackSummary sum;
  EXPECT_TRUE(packInput(*in, d.file("a.hfa"), PackOptions{}, nullptr, sum).isOk());
  return d.file("a.hfa");
}

// autzen packed without its tiles' stored levels (pack --no-levels), as n.hfa.
std::string packAutzenWithoutLevels(const test::TempDir& d) {
  auto in = InputSet::open({test::sharedData("lidar/autzen_trim.las")});
  EXPECT_TRUE(in.isOk());
  PackOptions opt;
  opt.storeLevels = false;
  PackSummary sum;
  EXPECT_TRUE(packInput(*in, d.file("n.hfa"), opt, nullptr, sum).isOk());
  return d.file("n.hfa");
}

// Every decoded cell taken from the streamer, waiting for the rest.
std::vector<uint32_t> drain(TileStreamer& s) {
  s.waitAll();
  return s.takeDecoded();
}

TEST(TileStreamer, WantedCellsComeFirstAndEveryCellComesOnce) {
  test::TempDir d;
  PackReader p;
  ASSERT_TRUE(p.open(packAutzen(d), PageLoad::kOnDemand).isOk());
  ASSERT_TRUE(p.onDemand());
  const uint32_t n = uint32_t(p.cells().size());
  ASSERT_GT(n, 1000u);
  TileStreamer s(p, 1);
  // The thread may have started in cell order: whatever it took before the wish, then the wish.
  std::vector<uint32_t> got = s.takeDecoded();
  const std::vector<uint32_t> wish = {n - 1, n / 2, n - 5};
  s.want(wish);
  std::vector<uint32_t> rest = drain(s);
  for (uint32_t c : wish) {
    const auto at = std::find(rest.begin(), rest.end(), c);
    if (std::find(got.begin(), got.end(), c) != got.end()) continue;  // taken before the wish
    ASSERT_NE(at, rest.end());
    // One cell in flight and one finished between the take and the wish may come before it.
    EXPECT_LE(at - rest.begin(), ptrdiff_t(2 + wish.size())) << "cell " << c;
  }
  got.insert(got.end(), rest.begin(), rest.end());
  std::sort(got.begin(), got.end());
  ASSERT_EQ(got.size(), n);
  for (uint32_t i = 0; i < n; ++i) EXPECT_EQ(got[i], i);
  EXPECT_TRUE(s.done());
  EXPECT_TRUE(s.error().isOk());
  // Decoded in the background, the pages are those decoded at open.
  PackReader whole;
  ASSERT_TRUE(whole.open(p.path()).isOk());
  ASSERT_EQ(std::memcmp(whole.heightPage(0), p.heightPage(0), p.pageTexels() * 2), 0);
}

TEST(TileStreamer, ADamagedTileIsNamedAndTheOthersStillCome) {
  test::TempDir d;
  const std::string path = packAutzen(d);
  PackReader z;
  ASSERT_TRUE(z.open(path).isOk());
  uint64_t off = 0, first[2];
  for (const SectionEntry& e : z.sectionTable())
    if (std::memcmp(e.id, "HGTZ", 4) == 0) off = e.offset;
  ASSERT_GT(off, 0u);
  std::memcpy(first, z.section("HGTZ").data() + 8 + 16 * 3, sizeof first);  // cell 3's tile
  std::vector<char> b(std::filesystem::file_size(path));
  std::ifstream(path, std::ios::binary).read(b.data(), std::streamsize(b.size()));
  b[off + first[0] + 1] ^= 0x5a;
  std::ofstream(d.file("bad.hfa"), std::ios::binary).write(b.data(), std::streamsize(b.size()));
  PackReader p;
  ASSERT_TRUE(p.open(d.file("bad.hfa"), PageLoad::kOnDemand).isOk());
  TileStreamer s(p, 2);
  EXPECT_EQ(drain(s).size(), p.cells().size());
  const Status e = s.error();
  ASSERT_FALSE(e.isOk());
  EXPECT_NE(e.message().find("bad.hfa: section HGTZ, tile of cell 3"), std::string::npos) << e.message();
}

// On request (--gpu-budget): only the cells asked for are decoded, with no page memory
// (PageLoad::kTiles), each into the caller's own tile (equal to the pack's); a released cell can
// be asked for again, one not released is not decoded twice.
TEST(TileStreamer, OnRequestOnlyTheCellsAskedForAndAgainOnceReleased) {
  test::TempDir d;
  const std::string path = packAutzen(d);
  PackReader p, whole;
  ASSERT_TRUE(p.open(path, PageLoad::kTiles).isOk());
  ASSERT_TRUE(whole.open(path).isOk());
  EXPECT_EQ(p.heightPage(0), nullptr);
  const uint32_t n = uint32_t(p.cells().size());
  std::vector<std::vector<uint16_t>> tiles(n);
  std::vector<std::atomic<int>> decodes(n);
  TileStreamer s(
      p, 2,
      [&](uint32_t i) {
        const CellRecord& c = p.cells()[i];
        tiles[i].assign(size_t(c.tileW + 2) * (c.tileH + 2), 0);
        ++decodes[i];
        return p.decodeCellInto(i, tiles[i].data(), nullptr, nullptr);
      },
      TileStreamer::Order::kOnRequest);
  EXPECT_TRUE(drain(s).empty()) << "nothing asked for, nothing decoded";
  const std::vector<uint32_t> wish = {n - 1, 7, n / 2};
  s.want(wish);
  std::vector<uint32_t> got = drain(s);
  std::sort(got.begin(), got.end());
  EXPECT_EQ(got, (std::vector<uint32_t>{7, n / 2, n - 1}));
  EXPECT_FALSE(s.done());
  for (uint32_t c : wish) {
    const CellRecord& r = whole.cells()[c];
    for (int j = -1; j <= int(r.tileH); ++j)
      for (int i = -1; i <= int(r.tileW); ++i)
        ASSERT_EQ(tiles[c][size_t(j + 1) * (r.tileW + 2) + size_t(i + 1)], whole.texel(r, i, j)) << "cell " << c;
  }
  s.release(7);
  s.want({7, n / 2});
  EXPECT_EQ(drain(s), std::vector<uint32_t>{7});
  EXPECT_EQ(decodes[7].load(), 2);
  EXPECT_EQ(decodes[n / 2].load(), 1);
  EXPECT_TRUE(s.error().isOk());
  // A pack opened for its metadata only cannot be decoded from: an error, not a crash.
  PackReader meta;
  ASSERT_TRUE(meta.open(path, PageLoad::kNone).isOk());
  std::vector<uint16_t> t(size_t(meta.cells()[0].tileW + 2) * (meta.cells()[0].tileH + 2));
  EXPECT_FALSE(meta.decodeCellInto(0, t.data(), nullptr, nullptr).isOk());
}

// Stored levels (MIPZ) on a real scan: the levels a far view asks for are the ones built from
// the tiles, texel for texel, and come without reading the tiles at all (a copy whose coded
// heights are overwritten still gives them; its level 0 is an error).
TEST(StoredLevels, AFarViewsLevelsAreTheTilesOwnAndNeedNoTile) {
  test::TempDir d;
  const std::string withPath = packAutzen(d), withoutPath = packAutzenWithoutLevels(d);
  PackReader with, without;
  ASSERT_TRUE(with.open(withPath, PageLoad::kTiles).isOk());
  ASSERT_TRUE(without.open(withoutPath, PageLoad::kTiles).isOk());
  EXPECT_TRUE(with.hasStoredLevels());
  EXPECT_FALSE(without.hasStoredLevels());
  const double ratio = double(std::filesystem::file_size(withPath)) / double(std::filesystem::file_size(withoutPath));
  std::printf("autzen: pack %.4fx the bytes with stored levels (MIPZ %zu bytes)\n", ratio, with.section("MIPZ").size());
  EXPECT_GT(ratio, 1.0);
  EXPECT_LT(ratio, 1.15);
  const uint32_t far = kStoredLevels[0];
  std::vector<uint32_t> storing;
  for (uint32_t i = 0; i < with.cells().size(); ++i) {
    const CellRecord& c = with.cells()[i];
    for (uint32_t keep : {far, far + 2}) {
      std::vector<TileImage> a, b;
      ASSERT_TRUE(buildLevels(with, i, keep, a).isOk());
      ASSERT_TRUE(buildLevels(without, i, keep, b).isOk());
      ASSERT_EQ(a.size(), b.size());
      for (size_t k = 0; k < a.size(); ++k) {
        ASSERT_EQ(a[k].w, b[k].w);
        ASSERT_EQ(a[k].heights, b[k].heights) << "cell " << i << " level " << k << " kept from " << keep;
        ASSERT_EQ(a[k].normals, b[k].normals) << "cell " << i << " level " << k;
        ASSERT_EQ(a[k].rgba, b[k].rgba) << "cell " << i << " level " << k;
      }
    }
    const bool has = levelCount(c.tileW, c.tileH) > far;
    EXPECT_EQ(with.storedLevelAtMost(i, 30), has ? far : 0u) << "cell " << i;
    EXPECT_EQ(with.storedLevelAtMost(i, far - 1), 0u);
    if (has) storing.push_back(i);
  }
  std::printf("%zu of %zu cells store level %u\n", storing.size(), with.cells().size(), far);
  ASSERT_GT(storing.size(), 20u);
  // A copy with every coded height tile overwritten (the index kept).
  std::ifstream in(withPath, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  PackHeader h;
  std::memcpy(&h, bytes.data(), sizeof h);
  for (uint32_t k = 0; k < h.sectionCount; ++k) {
    SectionEntry e;
    std::memcpy(&e, bytes.data() + h.sectionTableOffset + k * sizeof e, sizeof e);
    if (std::memcmp(e.id, "HGTZ", 4) != 0) continue;
    const uint64_t index = 8 + 16 * uint64_t(with.cells().size());
    std::fill(bytes.begin() + long(e.offset + index), bytes.begin() + long(e.offset + e.size), char(0xa5));
  }
  std::ofstream(d.file("damaged.hfa"), std::ios::binary).write(bytes.data(), long(bytes.size()));
  PackReader damaged;
  ASSERT_TRUE(damaged.open(d.file("damaged.hfa"), PageLoad::kTiles).isOk());
  for (uint32_t i : storing) {
    std::vector<TileImage> a, b;
    ASSERT_TRUE(buildLevels(damaged, i, far, a).isOk()) << "cell " << i << ": the far levels need no tile";
    ASSERT_TRUE(buildLevels(without, i, far, b).isOk());
    for (size_t k = far; k < a.size(); ++k) ASSERT_EQ(a[k].heights, b[k].heights) << "cell " << i << " level " << k;
    const Status s = buildLevels(damaged, i, 0, a);
    EXPECT_FALSE(s.isOk()) << "cell " << i << ": level 0 reads the damaged tile";
    EXPECT_NE(s.message().find("HGTZ"), std::string::npos) << s.message();
  }
}

class StreamingTest : public test::GlTest {};

// The same far views of autzen under a --gpu-budget, from a pack with stored levels and one
// without: the same image, bit for bit.
TEST_F(StreamingTest, StoredLevelsDrawTheSameBudgetImage) {
  test::TempDir d;
  PackReader with, without;
  ASSERT_TRUE(with.open(packAutzen(d), PageLoad::kTiles).isOk());
  ASSERT_TRUE(without.open(packAutzenWithoutLevels(d), PageLoad::kTiles).isOk());
  Renderer rw, rn;
  const uint64_t budget = uint64_t(4) << 20;
  ASSERT_TRUE(rw.init(with, true, budget).isOk());
  ASSERT_TRUE(rn.init(without, true, budget).isOk());
  const Eigen::Vector3d o(with.meta().origin), lo = o + Eigen::Vector3d(with.meta().boundsMin),
      hi = o + Eigen::Vector3d(with.meta().boundsMax);
  for (int v = 0; v < 3; ++v) {
    Camera cam;
    cam.target = (lo + hi) / 2;
    const double a = v * 2.1;
    cam.eye = cam.target + Eigen::Vector3d(std::cos(a) * 0.8, std::sin(a) * 0.8, 0.7) * (0.8 + 1.2 * v) * (hi - lo).norm();
    cam.up = Eigen::Vector3d::UnitZ();
    cam.width = cam.height = 96;
    FrameResult fa, fb;
    for (Renderer* r : {&rw, &rn}) {
      FrameResult& f = r == &rw ? fa : fb;
      for (int frames = 0; frames < 10000 && (frames == 0 || r->tilesPending()); ++frames)
        ASSERT_TRUE(r->render(cam, RenderSettings{}, f, kReadColor | kReadDepth).isOk());
      ASSERT_FALSE(r->tilesPending()) << "view " << v;
      ASSERT_TRUE(r->render(cam, RenderSettings{}, f, kReadColor | kReadDepth).isOk());
    }
    EXPECT_GT(fa.cellsDrawn + fa.stats.splats, 50u);
    EXPECT_EQ(fa.color.rgba, fb.color.rgba) << "view " << v;
    ASSERT_EQ(fa.depth.size(), fb.depth.size());
    EXPECT_EQ(std::memcmp(fa.depth.data(), fb.depth.data(), fa.depth.size() * sizeof(float)), 0) << "view " << v;
    EXPECT_EQ(rw.streamError(), "");
  }
}

// A real scan (autzen LAS, compressed pages): frames while tiles stream draw only resident
// cells and say how many visible cells they lack; once streaming ends the image is the one a
// pack uploaded whole gives, bit for bit.
TEST_F(StreamingTest, AStreamedPackEndsWithTheImageOfAWholeUpload) {
  test::TempDir d;
  packAutzen(d);
  PackReader whole, lazy;
  ASSERT_TRUE(whole.open(d.file("a.hfa")).isOk());
  ASSERT_TRUE(whole.compressedPages());
  ASSERT_TRUE(lazy.open(d.file("a.hfa"), PageLoad::kOnDemand).isOk());
  Renderer rw, rs;
  ASSERT_TRUE(rw.init(whole).isOk());
  EXPECT_FALSE(rw.tilesPending());
  Renderer bad;
  EXPECT_FALSE(bad.init(lazy).isOk()) << "pages on demand must be streamed";
  ASSERT_TRUE(rs.init(lazy, true).isOk());
  Camera cam;
  const Eigen::Vector3d o(whole.meta().origin), lo = o + Eigen::Vector3d(whole.meta().boundsMin),
      hi = o + Eigen::Vector3d(whole.meta().boundsMax);
  cam.target = (lo + hi) / 2;
  cam.eye = cam.target + Eigen::Vector3d(0.3, -0.8, 0.6) * (hi - lo).norm();
  cam.up = Eigen::Vector3d::UnitZ();
  cam.width = cam.height = 160;
  RenderSettings rset;
  FrameResult full, fr;
  ASSERT_TRUE(rw.render(cam, rset, full, true).isOk());
  ASSERT_EQ(full.stats.missing, 0u);
  ASSERT_GT(full.cellsDrawn, 100u);
  int frames = 0;
  uint32_t maxMissing = 0;
  while (rs.tilesPending() && frames < 100000) {
    ASSERT_TRUE(rs.render(cam, rset, fr, true).isOk());
    EXPECT_LE(fr.cellsDrawn + fr.stats.splats, full.cellsDrawn + full.stats.splats);
    maxMissing = std::max(maxMissing, fr.stats.missing);
    ++frames;
  }
  ASSERT_FALSE(rs.tilesPending());
  EXPECT_EQ(rs.tilesResident(), whole.cells().size());
  EXPECT_EQ(rs.streamError(), "");
  ASSERT_TRUE(rs.render(cam, rset, fr, true).isOk());
  std::printf("autzen: %d streamed frames (at most %u visible cells missing), then %u cells drawn\n", frames, maxMissing,
              fr.cellsDrawn);
  EXPECT_EQ(fr.stats.missing, 0u);
  EXPECT_EQ(fr.cellsDrawn, full.cellsDrawn);
  EXPECT_EQ(fr.color.rgba, full.color.rgba);
  ASSERT_EQ(fr.depth.size(), full.depth.size());
  EXPECT_EQ(std::memcmp(fr.depth.data(), full.depth.data(), fr.depth.size() * sizeof(float)), 0);
  // waitForTiles: a second streamed renderer made whole at once.
  PackReader lazy2;
  ASSERT_TRUE(lazy2.open(d.file("a.hfa"), PageLoad::kOnDemand).isOk());
  Renderer r2;
  ASSERT_TRUE(r2.init(lazy2, true).isOk());
  r2.waitForTiles();
  EXPECT_FALSE(r2.tilesPending());
  ASSERT_TRUE(r2.render(cam, rset, fr, true).isOk());
  EXPECT_EQ(fr.color.rgba, full.color.rgba);
}

// Streaming::kVisible (render without a budget), on autzen: a close-up decodes only the tiles it
// draws and gives the image of a whole upload, bit for bit; a view rendered before it is loaded
// lacks cells, and once loaded is the whole image too; waitForTiles decodes the rest, into the
// pages open decodes. A damaged tile fails the view that draws it, naming the file and the
// cell, and not a view that does not.
TEST_F(StreamingTest, AVisibleOnlyRenderDecodesWhatItDrawsAndDrawsTheWholeImage) {
  test::TempDir d;
  packAutzen(d);
  PackReader whole, lazy;
  ASSERT_TRUE(whole.open(d.file("a.hfa")).isOk());
  ASSERT_TRUE(lazy.open(d.file("a.hfa"), PageLoad::kOnDemand).isOk());
  Renderer rw, rv;
  ASSERT_TRUE(rw.init(whole).isOk());
  ASSERT_TRUE(rv.init(lazy, true, 0, Renderer::Streaming::kVisible).isOk());
  EXPECT_EQ(rv.tilesResident(), 0u);
  const uint32_t n = uint32_t(whole.cells().size());
  const Eigen::Vector3d o(whole.meta().origin), lo = o + Eigen::Vector3d(whole.meta().boundsMin),
      hi = o + Eigen::Vector3d(whole.meta().boundsMax);
  auto view = [&](double fx, double fy, double distance) {
    Camera c;
    c.target = lo + (hi - lo).cwiseProduct(Eigen::Vector3d(fx, fy, 0.3));
    c.eye = c.target + Eigen::Vector3d(0.2, -0.3, 1).normalized() * distance * (hi - lo).norm();
    c.up = Eigen::Vector3d::UnitZ();
    c.width = c.height = 128;
    return c;
  };
  const Camera close = view(0.4, 0.5, 0.08), far = view(0.5, 0.5, 1.2);
  const RenderSettings rset;
  auto sameImage = [&](const Camera& cam, const char* what) {
    FrameResult a, b;
    ASSERT_TRUE(rw.render(cam, rset, a, true).isOk());
    ASSERT_TRUE(rv.render(cam, rset, b, true).isOk());
    EXPECT_GT(a.cellsDrawn, 20u) << what;
    EXPECT_EQ(b.stats.missing, 0u) << what;
    EXPECT_FALSE(rv.tilesPending()) << what;
    EXPECT_EQ(b.cellsDrawn, a.cellsDrawn) << what;
    EXPECT_EQ(b.color.rgba, a.color.rgba) << what;
    ASSERT_EQ(b.depth.size(), a.depth.size());
    EXPECT_EQ(std::memcmp(b.depth.data(), a.depth.data(), a.depth.size() * sizeof(float)), 0) << what;
  };
  ASSERT_TRUE(rv.loadVisibleTiles(close, rset).isOk());
  const uint32_t closeTiles = rv.tilesResident();
  std::printf("autzen close-up: %u of %u tiles decoded\n", closeTiles, n);
  EXPECT_GT(closeTiles, 20u);
  EXPECT_LT(closeTiles, n / 3);
  sameImage(close, "close-up");
  FrameResult early;
  ASSERT_TRUE(rv.render(far, rset, early, true).isOk());
  EXPECT_GT(early.stats.missing, 100u) << "the far view's tiles were not loaded";
  EXPECT_TRUE(rv.tilesPending());
  ASSERT_TRUE(rv.loadVisibleTiles(far, rset).isOk());
  EXPECT_GT(rv.tilesResident(), closeTiles);
  sameImage(far, "far view");
  rv.waitForTiles();
  EXPECT_EQ(rv.tilesResident(), n);
  EXPECT_EQ(rv.streamError(), "");
  const uint64_t texels = whole.pageTexels();
  for (uint32_t p = 0; p < whole.meta().pageCount; ++p) {
    ASSERT_EQ(std::memcmp(lazy.heightPage(p), whole.heightPage(p), texels * 2), 0) << "page " << p;
    ASSERT_EQ(std::memcmp(lazy.normalPage(p), whole.normalPage(p), texels * kNormalBytes), 0) << "page " << p;
    ASSERT_EQ(std::memcmp(lazy.colorPage(p), whole.colorPage(p), texels * 4), 0) << "page " << p;
  }
  // A tile the far view draws and the close-up does not, damaged.
  CellCuller culler(whole.cells());
  VisibleSet vc, vf;
  culler.compute(close, close.eye - o, rw.nearPlane(), CullOptions{}, vc);
  culler.compute(far, far.eye - o, rw.nearPlane(), CullOptions{}, vf);
  std::vector<uint8_t> inClose(n, 0);
  for (const auto* l : {&vc.front, &vc.inside, &vc.splats})
    for (const DrawItem& it : *l) inClose[it.cell] = 1;
  uint32_t victim = n;
  for (const DrawItem& it : vf.front)
    if (!inClose[it.cell] && whole.cells()[it.cell].tileW > 2) victim = std::min(victim, it.cell);
  ASSERT_LT(victim, n);
  ASSERT_TRUE(test::damageHeightTile(d.file("a.hfa"), victim, d.file("damaged.hfa")));
  PackReader damaged;
  ASSERT_TRUE(damaged.open(d.file("damaged.hfa"), PageLoad::kOnDemand).isOk());
  Renderer rd;
  ASSERT_TRUE(rd.init(damaged, true, 0, Renderer::Streaming::kVisible).isOk());
  EXPECT_TRUE(rd.loadVisibleTiles(close, rset).isOk()) << "the close-up does not draw cell " << victim;
  const Status s = rd.loadVisibleTiles(far, rset);
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find(d.file("damaged.hfa")), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("HGTZ, tile of cell " + std::to_string(victim)), std::string::npos) << s.message();
}

// --gpu-budget a quarter of the atlas on the autzen LAS: the cache stays within it, each view
// settles, and the settled image agrees with the unlimited render (coverage and depth).
// Thresholds from the measured figures, with a margin.
TEST_F(StreamingTest, AGpuBudgetOfAQuarterOfTheAtlasDrawsTheSameScene) {
  test::TempDir d;
  packAutzen(d);
  PackReader whole, lazy;
  ASSERT_TRUE(whole.open(d.file("a.hfa")).isOk());
  ASSERT_TRUE(lazy.open(d.file("a.hfa"), PageLoad::kTiles).isOk());
  EXPECT_EQ(lazy.heightPage(0), nullptr) << "no page memory under a budget";
  Renderer rw, rb;
  ASSERT_TRUE(rw.init(whole).isOk());
  const uint64_t atlas = rw.gpuBytes();
  const uint64_t budget = atlas / 4;
  ASSERT_TRUE(rb.init(lazy, true, budget).isOk());
  EXPECT_LE(rb.gpuBytes(), budget + (uint64_t(1) << 20)) << "cache and cell table within the budget";
  EXPECT_EQ(rb.drawnMode(RenderMode::kExact), RenderMode::kParallax);
  EXPECT_NE(rb.modeProblem(RenderMode::kExact).find("--gpu-budget"), std::string::npos);
  const Eigen::Vector3d o(whole.meta().origin), lo = o + Eigen::Vector3d(whole.meta().boundsMin),
      hi = o + Eigen::Vector3d(whole.meta().boundsMax);
  const double texel = whole.meta().texelSize;
  uint32_t evicted = 0;
  for (int v = 0; v < 6; ++v) {
    Camera cam;
    cam.target = (lo + hi) / 2;
    const double a = v * M_PI / 3, dist = (v % 2 ? 0.35 : 0.9) * (hi - lo).norm();
    cam.eye = cam.target + Eigen::Vector3d(std::cos(a) * 0.8, std::sin(a) * 0.8, 0.6) * dist;
    cam.up = Eigen::Vector3d::UnitZ();
    cam.width = cam.height = 192;
    FrameResult full, fr;
    ASSERT_TRUE(rw.render(cam, RenderSettings{}, full, true).isOk());
    int frames = 0;
    for (; frames < 10000; ++frames) {
      ASSERT_TRUE(rb.render(cam, RenderSettings{}, fr, kReadColor | kReadDepth).isOk());
      evicted += fr.stats.evicted;
      EXPECT_LE(fr.stats.residentBytes, budget);
      if (!rb.tilesPending()) break;
    }
    ASSERT_FALSE(rb.tilesPending()) << "view " << v << " did not settle";
    ASSERT_TRUE(rb.render(cam, RenderSettings{}, fr, true).isOk());
    // Memory holds the levels the view plans (the plan keeps them within 70 % of the cache) and
    // their coarser ones (a third more): within the budget, also where a planned level found no
    // block and its cell is drawn coarser for now.
    EXPECT_GT(fr.stats.heldBytes, 0u);
    EXPECT_LE(fr.stats.heldBytes, budget) << "view " << v;
    const RenderAgreement g = compareRenders(full.depth, fr.depth, texel);
    ASSERT_GT(g.both, 1000u);
    std::printf("view %d: %d frames to settle, %.1f of %.1f MiB resident, %.1f MiB held, %u cells coarser to fit; IoU %.4f (%zu pixels only unlimited, %zu only budget), depth error median %.3f texels, p95 %.3f\n",
                v, frames + 1, fr.stats.residentBytes / 1048576.0, budget / 1048576.0, fr.stats.heldBytes / 1048576.0, fr.stats.coarsened, g.iou, g.onlyA, g.onlyB,
                g.depthMedian, g.depthP95);
    const double iou = g.iou, median = g.depthMedian;
    // Measured 0.976-0.992 (0.907-0.953 before the levels had coverage masks): coarse levels
    // still close sub-pixel holes (about 2:1 of the differences).
    EXPECT_GE(iou, 0.96) << "view " << v;
    EXPECT_LE(median, 1.0) << "view " << v;
  }
  std::printf("%u cells evicted over the orbit\n", evicted);
}

// A generated survey (sa_gen_terrain: rolling ground and box buildings, a LAS without normals)
// seen from afar, where every cell draws a coarse level: the levels' coverage masks keep level
// 0's coverage edges to a sixteenth of a coarse texel, so they lose about as many pixels as they
// gain, and few. Measured over the 4 views: 339 pixels lost against 369 gained, IoU 0.9974-0.9976
// (texels up to a whole pixel on screen instead of 0.71: 303 against 383, IoU 0.9971-0.9982).
// Before the masks, a coarse texel was covered where 0.4 of its footprint was: 548 lost against
// 1028 gained, IoU 0.9940-0.9949; at half, 1063 lost against 858, IoU 0.9928-0.9939. What
// differs now is mostly single pixels, a sub-pixel hole in the ground seen or not.
TEST_F(StreamingTest, APointPacksCoarseLevelsKeepItsCoverage) {
  test::TempDir d;
  const std::string gen = std::string(SA_GEN_TERRAIN) + " 300000 " + d.file("s.las") + " > /dev/null";
  ASSERT_EQ(std::system(gen.c_str()), 0) << "sa_gen_terrain failed";
  auto in = InputSet::open({d.file("s.las")});
  ASSERT_TRUE(in.isOk());
  PackSummary sum;
  ASSERT_TRUE(packInput(*in, d.file("s.hfa"), PackOptions{}, nullptr, sum).isOk());
  PackReader whole, lazy;
  ASSERT_TRUE(whole.open(d.file("s.hfa")).isOk());
  ASSERT_TRUE(lazy.open(d.file("s.hfa"), PageLoad::kTiles).isOk());
  ASSERT_EQ(whole.meta().flags & kPackFromTriangles, 0u);
  Renderer rw, rb;
  ASSERT_TRUE(rw.init(whole).isOk());
  ASSERT_TRUE(rb.init(lazy, true, rw.gpuBytes()).isOk());  // room for all: only the levels differ
  const Eigen::Vector3d o(whole.meta().origin), lo = o + Eigen::Vector3d(whole.meta().boundsMin),
      hi = o + Eigen::Vector3d(whole.meta().boundsMax);
  size_t onlyFull = 0, onlyBudget = 0, both = 0;
  for (int v = 0; v < 4; ++v) {
    Camera cam;
    cam.target = (lo + hi) / 2;
    const double a = 0.4 + v * M_PI / 2;
    cam.eye = cam.target + Eigen::Vector3d(std::cos(a) * 0.7, std::sin(a) * 0.7, 0.5) * (hi - lo).norm();
    cam.up = Eigen::Vector3d::UnitZ();
    cam.width = cam.height = 320;
    FrameResult full, fr;
    ASSERT_TRUE(rw.render(cam, RenderSettings{}, full, true).isOk());
    for (int frames = 0; frames < 10000 && (frames == 0 || rb.tilesPending()); ++frames)
      ASSERT_TRUE(rb.render(cam, RenderSettings{}, fr, kReadDepth).isOk());
    ASSERT_FALSE(rb.tilesPending()) << "view " << v;
    ASSERT_TRUE(rb.render(cam, RenderSettings{}, fr, true).isOk());
    // Every tile at level 0 would hold at least the pages' used texels (most of the atlas) at
    // 1.2x the bytes (a budget's texel is 12 bytes against the atlas's 10: it holds its mask),
    // in power-of-two blocks; the views hold 18.6-22.1 of 27.8 MiB, the far cells at coarse levels.
    EXPECT_LT(double(fr.stats.residentBytes), 0.85 * double(rw.gpuBytes())) << "view " << v << " draws coarse levels";
    const RenderAgreement g = compareRenders(full.depth, fr.depth, whole.meta().texelSize);
    std::printf("[survey-levels] view %d: IoU %.4f, %zu pixels only at full resolution, %zu only at the coarse levels; %.1f of %.1f MiB resident\n",
                v, g.iou, g.onlyA, g.onlyB, fr.stats.residentBytes / 1048576.0, rw.gpuBytes() / 1048576.0);
    onlyFull += g.onlyA, onlyBudget += g.onlyB, both += g.both;
  }
  ASSERT_GT(both, 40000u);
  EXPECT_LE(double(onlyFull), 1.5 * double(onlyBudget)) << "cracks at the coarse levels";
  EXPECT_LE(double(onlyBudget), 1.5 * double(onlyFull)) << "coverage grown at the coarse levels";
  EXPECT_GE(double(both) / double(both + onlyFull + onlyBudget), 0.996);
}

}  // namespace
}  // namespace sa
