#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

#include "../common/test_util.h"
#include "atlas/pack_file.h"
#include "atlas/packing.h"

namespace sa {
namespace {

std::vector<TileSize> randomTiles(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<uint32_t> side(1, 200);
  std::vector<TileSize> t(n);
  for (auto& s : t) s = {side(rng), side(rng)};
  return t;
}

TEST(Packing, TilesWithGuttersNeverOverlapAndStayInsidePages) {
  auto tiles = randomTiles(600, 3);
  uint64_t area = 0;
  for (auto& t : tiles) area += uint64_t(t.w + 2) * (t.h + 2);
  PackingResult r = packAtlas(tiles, 1024);
  const uint32_t pw = r.pageWidth, ph = r.pageHeight;
  ASSERT_EQ(r.placements.size(), tiles.size());
  std::vector<std::vector<int>> owner(r.pageCount, std::vector<int>(size_t(pw) * ph, -1));
  for (size_t i = 0; i < tiles.size(); ++i) {
    const auto& p = r.placements[i];
    ASSERT_LT(p.page, r.pageCount);
    // The slot including its one-texel gutter.
    ASSERT_GE(p.x, 1u);
    ASSERT_GE(p.y, 1u);
    ASSERT_LE(p.x + tiles[i].w + 1, pw);
    ASSERT_LE(p.y + tiles[i].h + 1, ph);
    for (uint32_t y = p.y - 1; y < p.y + tiles[i].h + 1; ++y)
      for (uint32_t x = p.x - 1; x < p.x + tiles[i].w + 1; ++x) {
        int& o = owner[p.page][size_t(y) * pw + x];
        ASSERT_EQ(o, -1) << "tiles " << o << " and " << i << " overlap at " << x << "," << y;
        o = int(i);
      }
  }
  double used = 0;
  for (auto& t : tiles) used += double(t.w) * t.h;
  const double occupancy = used / (double(pw) * ph * r.pageCount);
  std::printf("packing occupancy %.1f%% over %u page(s) of %ux%u\n", 100 * occupancy, r.pageCount, pw, ph);
  EXPECT_GT(occupancy, 0.6);
}

// A long thin tile (a sparse LAS strip) gets a long thin page, not a square mostly empty one.
TEST(Packing, ElongatedTilesGetElongatedPages) {
  const std::vector<TileSize> strip = {{2004, 20}};
  const PackingResult r = packAtlas(strip, 4096);
  EXPECT_EQ(r.pageCount, 1u);
  EXPECT_EQ(r.pageWidth, 2048u);
  EXPECT_EQ(r.pageHeight, 32u);
  const std::vector<TileSize> column = {{20, 2004}, {20, 1000}};
  const PackingResult c = packAtlas(column, 4096);
  EXPECT_LE(uint64_t(c.pageWidth) * c.pageHeight * c.pageCount, uint64_t(64) * 2048);
}

struct SmallPack {
  PackMeta meta{};
  std::vector<CellRecord> cells;
  std::vector<std::vector<uint16_t>> heights;
  std::vector<std::vector<uint8_t>> rgba;
  std::vector<std::vector<uint8_t>> normals;
};

SmallPack makePack(bool color, uint32_t pageWidth = 512, uint32_t pageHeight = 512) {
  SmallPack sp;
  auto tiles = randomTiles(40, 11);
  PackingResult r = packTiles(tiles, pageWidth, pageHeight);
  sp.meta.origin[0] = 512345.678;
  sp.meta.origin[1] = 5012345.25;
  sp.meta.origin[2] = 101.5;
  sp.meta.pageWidth = pageWidth;
  sp.meta.pageHeight = pageHeight;
  sp.meta.pageCount = r.pageCount;
  sp.meta.flags = (color ? uint32_t(kPackHasColor) : 0u) | uint32_t(kPackHasNormals);
  sp.meta.texelSize = 0.01;
  std::mt19937 rng(5);
  for (size_t i = 0; i < tiles.size(); ++i) {
    CellRecord c{};
    for (int a = 0; a < 3; ++a) c.origin[a] = double(i) * 0.1 + a;
    c.u[0] = c.v[1] = c.w[2] = 1;
    c.box[0] = -1; c.box[1] = 1; c.box[2] = -2; c.box[3] = 2; c.box[4] = -0.5; c.box[5] = 0.5;
    c.page = r.placements[i].page;
    c.tileX = r.placements[i].x;
    c.tileY = r.placements[i].y;
    c.tileW = uint16_t(tiles[i].w);
    c.tileH = uint16_t(tiles[i].h);
    c.level = uint8_t(i % 9);
    sp.cells.push_back(c);
    std::vector<uint16_t> h(size_t(c.tileW) * c.tileH);
    for (auto& v : h) v = uint16_t(rng());
    sp.heights.push_back(h);
    std::vector<uint8_t> col(h.size() * 4);
    for (auto& v : col) v = uint8_t(rng());
    sp.rgba.push_back(col);
    std::vector<uint8_t> nrm(h.size() * kNormalBytes);
    for (auto& v : nrm) v = uint8_t(rng());
    sp.normals.push_back(nrm);
  }
  return sp;
}

TEST(PackFile, RoundTripsBitExactlyWithGutters) {
  test::TempDir d;
  for (bool color : {false, true}) {
    SmallPack sp = makePack(color, 512, 256);  // pages need not be square
    PackWriter w;
    ASSERT_TRUE(w.open(d.file("p.hfa"), sp.meta, sp.cells, "note").isOk());
    for (uint32_t i = 0; i < sp.cells.size(); ++i)
      ASSERT_TRUE(w.writeTile(i, sp.heights[i].data(), sp.normals[i].data(), color ? sp.rgba[i].data() : nullptr).isOk());
    ASSERT_TRUE(w.finish().isOk());
    PackReader r;
    Status s = r.open(d.file("p.hfa"));
    ASSERT_TRUE(s.isOk()) << s.message();
    ASSERT_TRUE(r.verifyPages().isOk());
    EXPECT_EQ(r.note(), "note");
    EXPECT_EQ(r.hasColor(), color);
    EXPECT_EQ(r.meta().origin[1], 5012345.25);
    ASSERT_EQ(r.cells().size(), sp.cells.size());
    EXPECT_EQ(std::memcmp(r.cells().data(), sp.cells.data(), sp.cells.size() * sizeof(CellRecord)), 0);
    for (uint32_t i = 0; i < sp.cells.size(); ++i) {
      const CellRecord& c = sp.cells[i];
      for (int j = -1; j <= int(c.tileH); ++j)
        for (int k = -1; k <= int(c.tileW); ++k) {
          // Interior texels exact; gutter texels repeat the nearest edge texel.
          const int sj = std::clamp(j, 0, int(c.tileH) - 1), sk = std::clamp(k, 0, int(c.tileW) - 1);
          ASSERT_EQ(r.texel(c, k, j), sp.heights[i][size_t(sj) * c.tileW + sk]) << "cell " << i << " " << k << "," << j;
          ASSERT_EQ(std::memcmp(r.normalTexel(c, k, j), &sp.normals[i][(size_t(sj) * c.tileW + sk) * kNormalBytes], kNormalBytes), 0);
          if (color) {
            const uint8_t* page = r.colorPage(c.page);
            const size_t t = (size_t(c.tileY + j) * r.meta().pageWidth + c.tileX + k) * 4;
            ASSERT_EQ(std::memcmp(page + t, &sp.rgba[i][(size_t(sj) * c.tileW + sk) * 4], 4), 0);
          }
        }
    }
  }
}

// Compressed pages (FORMAT.md): the same pages as the raw pack, byte for byte, whatever the
// texels (random ones, which do not compress, and smooth ones, which do); a damaged or
// mis-sized tile is an error naming the file, the section and the cell.
TEST(PackFile, CompressedPagesDecodeToTheRawPagesAndDamageIsNamed) {
  test::TempDir d;
  for (bool smooth : {false, true}) {
    SmallPack sp = makePack(true, 512, 256);
    if (smooth)
      for (size_t i = 0; i < sp.cells.size(); ++i) {
        const CellRecord& c = sp.cells[i];
        for (int j = 0; j < c.tileH; ++j)
          for (int k = 0; k < c.tileW; ++k) {
            const size_t t = size_t(j) * c.tileW + k;
            sp.heights[i][t] = (k * 7 + j * 3) % 5 == 0 ? 0 : uint16_t(20000 + 40 * k + 13 * j + (k * j) % 3);
            for (int b = 0; b < kNormalBytes; ++b) sp.normals[i][t * kNormalBytes + b] = uint8_t(100 + (k + j) / 8 + b);
            for (int b = 0; b < 4; ++b) sp.rgba[i][t * 4 + b] = uint8_t(b == 3 ? 255 : 60 + b * 20 + k / 4);
          }
      }
    std::vector<uint64_t> sizes;
    for (bool compress : {false, true}) {
      PackWriter w;
      w.setCompressPages(compress);
      const std::string path = d.file(compress ? "z.hfa" : "raw.hfa");
      ASSERT_TRUE(w.open(path, sp.meta, sp.cells, "note").isOk());
      // Compressed: tiles coded as they come, last cell first (threads finish in any order);
      // the final file holds them in cell order.
      const uint32_t n = uint32_t(sp.cells.size());
      for (uint32_t k = 0; k < n; ++k) {
        const uint32_t i = compress ? n - 1 - k : k;
        ASSERT_TRUE(w.writeTile(i, sp.heights[i].data(), sp.normals[i].data(), sp.rgba[i].data()).isOk());
      }
      const std::string temp = w.tempPath();
      if (compress) {
        EXPECT_GT(w.codedBytes(), 0u);
        EXPECT_EQ(std::filesystem::file_size(temp), w.codedBytes()) << "only coded tiles are written before finish";
      }
      ASSERT_TRUE(w.finish().isOk());
      EXPECT_FALSE(std::filesystem::exists(temp)) << "the temporary is gone";
      sizes.push_back(std::filesystem::file_size(path));
    }
    PackReader raw, z;
    ASSERT_TRUE(raw.open(d.file("raw.hfa")).isOk());
    Status s = z.open(d.file("z.hfa"));
    ASSERT_TRUE(s.isOk()) << s.message();
    ASSERT_TRUE(z.verifyPages().isOk());
    EXPECT_FALSE(raw.compressedPages());
    EXPECT_TRUE(z.compressedPages());
    EXPECT_TRUE(z.section("HGHT").empty());
    EXPECT_EQ(z.note(), "note");
    const uint64_t P = raw.pageTexels();
    for (uint32_t p = 0; p < raw.meta().pageCount; ++p) {
      ASSERT_EQ(std::memcmp(raw.heightPage(p), z.heightPage(p), P * 2), 0) << "page " << p;
      ASSERT_EQ(std::memcmp(raw.normalPage(p), z.normalPage(p), P * kNormalBytes), 0) << "page " << p;
      ASSERT_EQ(std::memcmp(raw.colorPage(p), z.colorPage(p), P * 4), 0) << "page " << p;
    }
    std::printf("%s texels: raw pack %llu bytes, compressed %llu (%.2fx)\n", smooth ? "smooth" : "random",
                (unsigned long long)sizes[0], (unsigned long long)sizes[1], double(sizes[0]) / double(sizes[1]));
    if (smooth) {
      EXPECT_GT(double(sizes[0]) / double(sizes[1]), 4.0);
    }
    // Metadata only: no pages decoded.
    PackReader meta;
    ASSERT_TRUE(meta.open(d.file("z.hfa"), PageLoad::kNone).isOk());
    EXPECT_EQ(meta.heightPage(0), nullptr);
    EXPECT_TRUE(meta.hasColor());
    // On demand: a tile is zero until its cell is decoded, then the same bytes; in any order.
    PackReader lazy;
    ASSERT_TRUE(lazy.open(d.file("z.hfa"), PageLoad::kOnDemand).isOk());
    EXPECT_TRUE(lazy.onDemand());
    EXPECT_FALSE(z.onDemand());
    const CellRecord& c0 = lazy.cells()[0];
    EXPECT_EQ(lazy.texel(c0, 0, 0), 0);
    const uint32_t n = uint32_t(lazy.cells().size());
    for (uint32_t k = 0; k < n; ++k) ASSERT_TRUE(lazy.decodeCell((k * 7 + 3) % n).isOk());
    for (uint32_t p = 0; p < raw.meta().pageCount; ++p) {
      ASSERT_EQ(std::memcmp(raw.heightPage(p), lazy.heightPage(p), P * 2), 0) << "page " << p;
      ASSERT_EQ(std::memcmp(raw.normalPage(p), lazy.normalPage(p), P * kNormalBytes), 0) << "page " << p;
      ASSERT_EQ(std::memcmp(raw.colorPage(p), lazy.colorPage(p), P * 4), 0) << "page " << p;
    }
    EXPECT_TRUE(raw.decodeCell(0).isOk()) << "raw pages: nothing to decode";
  }
  // Damage inside the HGTZ section's first tile: named, with its cell.
  const std::string path = d.file("z.hfa");
  PackReader z;
  ASSERT_TRUE(z.open(path).isOk());
  uint64_t off = 0;
  for (const SectionEntry& e : z.sectionTable())
    if (std::memcmp(e.id, "HGTZ", 4) == 0) off = e.offset;
  ASSERT_GT(off, 0u);
  uint64_t first[2];
  std::memcpy(first, z.section("HGTZ").data() + 8, sizeof first);
  std::vector<char> bytes(std::filesystem::file_size(path));
  std::ifstream(path, std::ios::binary).read(bytes.data(), std::streamsize(bytes.size()));
  auto openDamaged = [&](uint64_t at, char value) {
    std::vector<char> b = bytes;
    b[at] = value;
    const std::string p = d.file("damaged.hfa");
    std::ofstream(p, std::ios::binary | std::ios::trunc).write(b.data(), std::streamsize(b.size()));
    PackReader r;
    return r.open(p);
  };
  Status s = openDamaged(off + first[0] + 1, char(bytes[off + first[0] + 1] ^ 0x5a));  // the zstd frame's header
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("damaged.hfa: section HGTZ, tile of cell 0"), std::string::npos) << s.message();
  {  // on demand the pack opens; the damaged tile is the error of its cell alone
    PackReader lazy;
    ASSERT_TRUE(lazy.open(d.file("damaged.hfa"), PageLoad::kOnDemand).isOk());
    s = lazy.decodeCell(0);
    EXPECT_NE(s.message().find("damaged.hfa: section HGTZ, tile of cell 0"), std::string::npos) << s.message();
    EXPECT_TRUE(lazy.decodeCell(1).isOk());
  }
  s = openDamaged(off, char(bytes[off] + 1));  // the tile count
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("does not index"), std::string::npos) << s.message();
  s = openDamaged(off + 8 + 7, char(0x40));  // the first tile's offset far outside the section
  ASSERT_FALSE(s.isOk());
  EXPECT_NE(s.message().find("lies outside the section"), std::string::npos) << s.message();
}

TEST(PackFile, HeaderBytesMatchTheSpec) {
  test::TempDir d;
  SmallPack sp = makePack(false);
  PackWriter w;
  ASSERT_TRUE(w.open(d.file("p.hfa"), sp.meta, sp.cells, "").isOk());
  ASSERT_TRUE(w.finish().isOk());
  std::ifstream f(d.file("p.hfa"), std::ios::binary);
  std::vector<unsigned char> b(64 + 32 * 4);
  f.read(reinterpret_cast<char*>(b.data()), std::streamsize(b.size()));
  EXPECT_EQ(std::string(reinterpret_cast<char*>(b.data()), 8), std::string("SCANHFA\0", 8));
  EXPECT_EQ(b[8], 2);                                        // version 2, little-endian
  EXPECT_EQ(b[12], 0x04); EXPECT_EQ(b[15], 0x01);            // byte-order mark
  EXPECT_EQ(b[16], 5);                                       // META CELL HGHT NRML NOTE
  EXPECT_EQ(b[20], 64);                                      // header size
  EXPECT_EQ(b[32], 64);                                      // section table offset
  EXPECT_EQ(std::string(reinterpret_cast<char*>(&b[64]), 4), "META");
  EXPECT_EQ(b[64 + 9], 0x10);                                // META at offset 4096
  EXPECT_EQ(std::string(reinterpret_cast<char*>(&b[96]), 4), "CELL");
  EXPECT_EQ(std::string(reinterpret_cast<char*>(&b[128]), 4), "HGHT");
  EXPECT_EQ(std::string(reinterpret_cast<char*>(&b[160]), 4), "NRML");
}

TEST(PackFile, ReaderRejectsCorruptTruncatedAndNewerFiles) {
  test::TempDir d;
  SmallPack sp = makePack(false);
  PackWriter w;
  ASSERT_TRUE(w.open(d.file("p.hfa"), sp.meta, sp.cells, "").isOk());
  for (uint32_t i = 0; i < sp.cells.size(); ++i) ASSERT_TRUE(w.writeTile(i, sp.heights[i].data(), sp.normals[i].data(), nullptr).isOk());
  ASSERT_TRUE(w.finish().isOk());
  std::ifstream in(d.file("p.hfa"), std::ios::binary);
  std::vector<char> good((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto expectError = [&](std::vector<char> bytes, const std::string& needle) {
    test::writeBytes(d.file("bad.hfa"), bytes);
    PackReader r;
    Status s = r.open(d.file("bad.hfa"));
    if (s.isOk()) s = r.verifyPages();
    ASSERT_FALSE(s.isOk()) << needle;
    EXPECT_NE(s.message().find(needle), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("bad.hfa"), std::string::npos) << s.message();
  };
  auto v = good;
  v[8] = 3;
  expectError(v, "version 3 is newer");
  v = good;
  v[8] = 1;
  expectError(v, "made by an older scanatlas");
  v = good;
  v[0] = 'X';
  expectError(v, "bad magic");
  v = good;
  v.resize(v.size() / 2);
  expectError(v, "truncated");
  v = good;
  v[4096 + 112] ^= 1;  // cell count inside META
  expectError(v, "META checksum");
  uint64_t hght = 0;  // the HGHT section's offset, from its section-table entry (the third)
  std::memcpy(&hght, &good[64 + 2 * 32 + 8], 8);
  v = good;
  v[hght + 100] ^= 0x5a;  // a height texel in the first page
  expectError(v, "HGHT checksum");
  v = good;
  v[v.size() - 100] ^= 0x5a;  // a normal texel in the last page
  expectError(v, "NRML checksum");
  expectError(std::vector<char>(10, 0), "too short");
  // A section table offset near 2^64: offset + table size wrapped and passed the bounds check
  // (fuzz_pack finding; zlib then read unmapped memory).
  v = good;
  for (int i = 0; i < 8; ++i) v[32 + i] = char(0xff);  // sectionTableOffset
  expectError(v, "corrupt section table");
}

// Every pack-reader input the fuzzer found (fuzz/regressions/pack/) is refused as bad input
// naming the file.
TEST(PackFile, StoredFuzzFindingsAreBadInput) {
  int n = 0;
  for (const auto& f : std::filesystem::directory_iterator(std::string(SA_SOURCE_DIR) + "/fuzz/regressions/pack")) {
    ++n;
    PackReader r;
    Status s = r.open(f.path().string());
    if (s.isOk()) s = r.verifyPages();
    ASSERT_FALSE(s.isOk()) << f.path();
    EXPECT_EQ(s.kind(), ErrorKind::kBadInput) << s.message();
    EXPECT_NE(s.message().find(f.path().filename().string()), std::string::npos) << s.message();
  }
  EXPECT_GE(n, 1);
}

}  // namespace
}  // namespace sa

#include "atlas/verify.h"

namespace sa {
namespace {

TEST(Verify, SoundPackPassesAndDamageIsReported) {
  test::TempDir d;
  SmallPack sp = makePack(false);
  for (auto& c : sp.cells) c.pointCount = 1;
  sp.meta.sourcePoints = sp.cells.size();
  {
    PackWriter w;
    ASSERT_TRUE(w.open(d.file("ok.hfa"), sp.meta, sp.cells, "").isOk());
    for (uint32_t i = 0; i < sp.cells.size(); ++i) ASSERT_TRUE(w.writeTile(i, sp.heights[i].data(), sp.normals[i].data(), nullptr).isOk());
    ASSERT_TRUE(w.finish().isOk());
  }
  PackReader ok;
  ASSERT_TRUE(ok.open(d.file("ok.hfa")).isOk());
  VerifyReport r = verifyPack(ok);
  EXPECT_TRUE(r.problems.empty()) << r.problems[0];
  EXPECT_EQ(r.cellsChecked, sp.cells.size());
  // Two tiles at the same place, a skewed frame and a wrong point count: all reported.
  SmallPack bad = sp;
  bad.cells[1].page = bad.cells[0].page;
  bad.cells[1].tileX = bad.cells[0].tileX;
  bad.cells[1].tileY = bad.cells[0].tileY;
  bad.cells[2].u[1] = 0.5;
  bad.meta.sourcePoints += 3;
  {
    PackWriter w;
    ASSERT_TRUE(w.open(d.file("bad.hfa"), bad.meta, bad.cells, "").isOk());
    ASSERT_TRUE(w.finish().isOk());
  }
  PackReader br;
  ASSERT_TRUE(br.open(d.file("bad.hfa")).isOk());
  r = verifyPack(br);
  std::string all;
  for (const auto& p : r.problems) all += p + "\n";
  EXPECT_NE(all.find("overlaps"), std::string::npos) << all;
  EXPECT_NE(all.find("not orthonormal"), std::string::npos) << all;
  EXPECT_NE(all.find("META counts"), std::string::npos) << all;
}

}  // namespace
}  // namespace sa
