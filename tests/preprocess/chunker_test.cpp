// Chunk files (preprocess/chunker.cpp): frames of byte-shuffled, zstd-compressed records. A chunk
// round-trips exactly (several frames, a frame's worth plus one, rounded positions, wrapping
// differences), is smaller than its raw records (rounded positions smaller still),
// and a truncated, damaged or over-long file is an error naming it, never points made up.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <random>
#include <set>

#include "../common/test_util.h"
#include "formats/source.h"
#include "preprocess/chunker.h"

namespace sa {
namespace {

std::vector<ChunkPoint> scanLikePoints(size_t n) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1, 1);
  std::vector<ChunkPoint> v(n);
  for (size_t i = 0; i < n; ++i) {
    ChunkPoint& p = v[i];
    for (int a = 0; a < 3; ++a) p.q[a] = 0x40000000u + uint32_t(i * 977 + a * 131) % 0x01000000u;
    for (int a = 0; a < 3; ++a) p.n[a] = u(rng);
    p.rgb[0] = uint8_t(i), p.rgb[1] = 7, p.rgb[2] = uint8_t(i >> 8);
    p.flags = kChunkHasNormal;
    p.scan = uint16_t(i % 3);
    p.spacing = 1024;
    p.vid = uint32_t(i);
  }
  return v;
}

// roundToChunkNormal against the libm form it replaces, bit for bit: a spread of every float's
// bit patterns (both signs, subnormals to infinities), and the values around each tie in [-1, 1].
TEST(ChunkNormal, RoundingIsTheLibmFormBitForBit) {
  auto libm = [](float v) { return std::ldexp(std::nearbyint(std::ldexp(v, kChunkNormalBits)), -kChunkNormalBits); };
  auto bitsOf = [](float v) {
    uint32_t u;
    std::memcpy(&u, &v, 4);
    return u;
  };
  auto check = [&](float v) {
    const float want = libm(v), got = roundToChunkNormal(v);
    if (std::isnan(want)) {
      EXPECT_TRUE(std::isnan(got)) << v;
    } else {
      ASSERT_EQ(bitsOf(got), bitsOf(want)) << v;
    }
  };
  for (uint64_t b = 0; b < (1ull << 32); b += 4099) {
    const uint32_t u = uint32_t(b);
    float v;
    std::memcpy(&v, &u, 4);
    check(v);
  }
  const float step = std::ldexp(1.0f, -kChunkNormalBits);
  for (int k = -(1 << kChunkNormalBits); k < (1 << kChunkNormalBits); k += 7) {
    const float tie = (float(k) + 0.5f) * step;
    for (const float v : {tie, std::nextafter(tie, -2.0f), std::nextafter(tie, 2.0f), float(k) * step}) check(v);
  }
  for (const float v : {0.0f, -0.0f, 1e-40f, -1e-40f, 1.0f, -1.0f, 3e38f, -INFINITY, INFINITY, NAN}) check(v);
}

TEST(ChunkFile, RoundTripsExactlyAndIsSmallerThanItsRecords) {
  test::TempDir dir;
  const std::vector<ChunkPoint> pts = scanLikePoints((1 << 16) * 2 + 1);  // three frames
  const std::string path = dir.file("c.bin");
  const uint64_t before = chunkBytesWritten();
  ASSERT_TRUE(saveChunk(path, pts).isOk());
  const uint64_t written = chunkBytesWritten() - before;
  EXPECT_EQ(written, std::filesystem::file_size(path));
  EXPECT_LT(written, pts.size() * sizeof(ChunkPoint));
  std::printf("[chunk] %zu records: %llu bytes on disk, %zu raw (%.2fx)\n", pts.size(), (unsigned long long)written,
              pts.size() * sizeof(ChunkPoint), double(pts.size() * sizeof(ChunkPoint)) / double(written));
  ChunkInfo c;
  c.path = path;
  c.count = pts.size();
  ChunkRecords back;
  ASSERT_TRUE(loadChunk(c, back).isOk());
  ASSERT_EQ(back.size(), pts.size());
  EXPECT_EQ(std::memcmp(back.data(), pts.data(), pts.size() * sizeof(ChunkPoint)), 0);
}

std::vector<ChunkPoint> roundTrip(const test::TempDir& dir, const std::vector<ChunkPoint>& pts, uint64_t& bytes) {
  const std::string path = dir.file("r.bin");
  const uint64_t before = chunkBytesWritten();
  EXPECT_TRUE(saveChunk(path, pts).isOk());
  bytes = chunkBytesWritten() - before;
  ChunkInfo c;
  c.path = path;
  c.count = pts.size();
  ChunkRecords back;
  EXPECT_TRUE(loadChunk(c, back).isOk());
  return {back.begin(), back.end()};
}

// Pass A rounds a point chunk's positions to a step under its spacing and writes them in cell
// order: the frames shift out the zero low bits and store differences. Such positions cost far
// fewer bytes than the same ones with noise in their low bits, and both come back exactly, as do
// differences that wrap (0 next to 0xffffffff).
TEST(ChunkFile, RoundedPositionsInCellOrderCostFewerBytesAndComeBackExactly) {
  test::TempDir dir;
  std::mt19937 rng(11);
  std::vector<ChunkPoint> noisy = scanLikePoints(50000);
  for (size_t i = 0; i < noisy.size(); ++i)  // a walk over a surface: neighbours in order
    for (int a = 0; a < 3; ++a) noisy[i].q[a] = 0x20000000u + uint32_t(i / 7 % 4096) * 3001u * (a + 1) + (rng() & 0xfffu);
  std::vector<ChunkPoint> rounded = noisy;
  for (ChunkPoint& p : rounded)
    for (uint32_t& q : p.q) q &= ~0xfffu;
  uint64_t noisyBytes = 0, roundedBytes = 0;
  const std::vector<ChunkPoint> a = roundTrip(dir, noisy, noisyBytes), b = roundTrip(dir, rounded, roundedBytes);
  ASSERT_EQ(a.size(), noisy.size());
  ASSERT_EQ(b.size(), rounded.size());
  EXPECT_EQ(std::memcmp(a.data(), noisy.data(), noisy.size() * sizeof(ChunkPoint)), 0);
  EXPECT_EQ(std::memcmp(b.data(), rounded.data(), rounded.size() * sizeof(ChunkPoint)), 0);
  std::printf("[chunk] 50000 records: %llu bytes with 12 noisy low bits, %llu rounded\n", (unsigned long long)noisyBytes,
              (unsigned long long)roundedBytes);
  EXPECT_LT(double(roundedBytes), 0.8 * double(noisyBytes));

  std::vector<ChunkPoint> extremes = scanLikePoints(1000);
  for (size_t i = 0; i < extremes.size(); ++i)
    for (int a = 0; a < 3; ++a) extremes[i].q[a] = (i + a) % 2 ? 0xffffffffu : uint32_t(i % 5);
  uint64_t bytes = 0;
  const std::vector<ChunkPoint> c = roundTrip(dir, extremes, bytes);
  ASSERT_EQ(c.size(), extremes.size());
  EXPECT_EQ(std::memcmp(c.data(), extremes.data(), extremes.size() * sizeof(ChunkPoint)), 0);
}

TEST(ChunkFile, DamagedOrMiscountedFilesAreErrorsNamingTheFile) {
  test::TempDir dir;
  const std::vector<ChunkPoint> pts = scanLikePoints(5000);
  const std::string path = dir.file("c.bin");
  ASSERT_TRUE(saveChunk(path, pts).isOk());
  const auto size = std::filesystem::file_size(path);
  auto expectError = [&](const std::string& file, uint64_t count, const char* what) {
    ChunkInfo c;
    c.path = file;
    c.count = count;
    ChunkRecords back;
    Status s = loadChunk(c, back);
    ASSERT_FALSE(s.isOk()) << what;
    EXPECT_NE(s.message().find(file), std::string::npos) << what << ": " << s.message();
  };
  expectError(path, pts.size() + 1, "more points recorded than the file holds");
  expectError(path, pts.size() - 1, "fewer points recorded than the file holds");
  std::filesystem::copy_file(path, dir.file("short.bin"));
  std::filesystem::resize_file(dir.file("short.bin"), size - 10);
  expectError(dir.file("short.bin"), pts.size(), "truncated");
  {
    std::filesystem::copy_file(path, dir.file("bad.bin"));
    std::FILE* f = std::fopen(dir.file("bad.bin").c_str(), "r+b");
    ASSERT_NE(f, nullptr);
    std::fseek(f, 20, SEEK_SET);
    const char junk[16] = "not zstd data!!";
    std::fwrite(junk, 1, sizeof junk, f);
    std::fclose(f);
    expectError(dir.file("bad.bin"), pts.size(), "damaged frame");
  }
  {
    std::FILE* f = std::fopen(dir.file("huge.bin").c_str(), "wb");
    const uint32_t head[3] = {0xffffffffu, 12, 0};
    std::fwrite(head, 4, 3, f);
    std::fclose(f);
    expectError(dir.file("huge.bin"), 10, "a frame header claiming 4 billion records");
  }
  expectError(dir.file("missing.bin"), 10, "missing file");
}

// `pts` written to dir/p.ply and opened.
Result<InputSet> openPly(const test::TempDir& dir, const std::vector<Eigen::Vector3d>& pts) {
  test::writePointsPly(dir.file("p.ply"), pts, nullptr);
  return InputSet::open({dir.file("p.ply")});
}

// The input's bounds and a quantizer over them, as the pipeline makes one.
Quantizer quantizerOf(const InputSet& in, BoundsInfo& b) {
  EXPECT_TRUE(computeBounds(in, b, nullptr, false, false).isOk());
  Quantizer qz;
  qz.cubeSize = (b.max - b.min).maxCoeff() * 1.0001;
  qz.cubeMin = Eigen::Vector3d::Constant(-qz.cubeSize / 2);
  return qz;
}

// Distributing with a plan (a counting read first) ends with the chunks that splitting over-full
// chunk files ends with: the same nodes, counts, order and records, each record written once.
TEST(Distribute, PlannedChunksAreTheSplitChunksWrittenOnce) {
  test::TempDir dir;
  // A dense patch in one corner and a sparse sheet: nodes over-full at different levels.
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 60000; ++i) pts.emplace_back(0.2 * u(rng), 0.2 * u(rng), 0.01 * u(rng));
  for (int i = 0; i < 20000; ++i) pts.emplace_back(u(rng), u(rng), 0.05 * u(rng));
  auto in = openPly(dir, pts);
  ASSERT_TRUE(in.isOk());
  BoundsInfo b;
  const Quantizer qz = quantizerOf(*in, b);
  std::vector<ChunkInfo> chunks[2];
  uint64_t records[2];
  for (int planned = 0; planned < 2; ++planned) {
    DistributeOptions o;
    o.maxPointsPerChunk = 3000;
    o.origin = (b.min + b.max) / 2;
    o.plan = planned;
    std::filesystem::create_directory(dir.file(planned ? "plan" : "split"));
    o.scratchDir = dir.file(planned ? "plan" : "split");
    DistributeResult r;
    const uint64_t before = chunkRecordBytesWritten();
    ASSERT_TRUE(distributePoints(*in, qz, o, r, nullptr).isOk());
    records[planned] = (chunkRecordBytesWritten() - before) / sizeof(ChunkPoint);
    chunks[planned] = r.chunks;
  }
  std::printf("[distribute] %zu chunks; records written: split %llu, planned %llu for %zu points\n", chunks[1].size(),
              (unsigned long long)records[0], (unsigned long long)records[1], pts.size());
  EXPECT_EQ(records[1], pts.size()) << "every record written once";
  EXPECT_GT(records[0], pts.size()) << "splitting rewrites the over-full chunks' records";
  ASSERT_EQ(chunks[0].size(), chunks[1].size());
  EXPECT_GT(chunks[1].size(), 10u);
  std::set<int> levels;
  for (size_t i = 0; i < chunks[1].size(); ++i) {
    const ChunkInfo &s = chunks[0][i], &p = chunks[1][i];
    EXPECT_EQ(s.level, p.level);
    EXPECT_EQ(s.ix, p.ix);
    EXPECT_EQ(s.iy, p.iy);
    EXPECT_EQ(s.iz, p.iz);
    EXPECT_EQ(s.count, p.count);
    EXPECT_LE(p.count, 3000u);
    levels.insert(p.level);
    ChunkRecords a, c;
    ASSERT_TRUE(loadChunk(s, a).isOk());
    ASSERT_TRUE(loadChunk(p, c).isOk());
    ASSERT_EQ(a.size(), c.size());
    EXPECT_EQ(std::memcmp(a.data(), c.data(), a.size() * sizeof(ChunkPoint)), 0) << "chunk " << i;
  }
  EXPECT_GE(levels.size(), 2u) << "chunks at several levels";
}

// A point input that fits one chunk, distributed in memory, holds the records a chunk file
// would: no file is written, loading hands them over once, saving gives them back. Past the
// chunk's size the chunks are files as before.
TEST(Distribute, OneChunkHeldInMemoryHoldsWhatItsFileWould) {
  test::TempDir dir;
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 5000; ++i) pts.emplace_back(u(rng), u(rng), 0.05 * u(rng));
  auto in = openPly(dir, pts);
  ASSERT_TRUE(in.isOk());
  BoundsInfo b;
  const Quantizer qz = quantizerOf(*in, b);
  auto distribute = [&](const char* sub, bool inMemory, uint64_t maxPoints, std::vector<ChunkInfo>& chunks) {
    DistributeOptions o;
    o.maxPointsPerChunk = maxPoints;
    o.origin = (b.min + b.max) / 2;
    o.inMemory = inMemory;
    std::filesystem::create_directory(dir.file(sub));
    o.scratchDir = dir.file(sub);
    DistributeResult r;
    const Status s = distributePoints(*in, qz, o, r, nullptr);
    ASSERT_TRUE(s.isOk()) << s.message();
    chunks = r.chunks;
  };
  std::vector<ChunkInfo> files, held, over;
  distribute("files", false, 8000, files);
  const uint64_t written = chunkBytesWritten();
  distribute("held", true, 8000, held);
  EXPECT_EQ(chunkBytesWritten(), written) << "a held chunk writes nothing";
  EXPECT_TRUE(std::filesystem::is_empty(dir.file("held")));
  ASSERT_EQ(files.size(), 1u);
  ASSERT_EQ(held.size(), 1u);
  EXPECT_EQ(files[0].held, nullptr);
  ASSERT_NE(held[0].held, nullptr);
  EXPECT_EQ(held[0].count, files[0].count);
  ChunkRecords a, c;
  ASSERT_TRUE(loadChunk(files[0], a).isOk());
  ASSERT_TRUE(loadChunk(held[0], c).isOk());
  ASSERT_EQ(a.size(), pts.size());
  ASSERT_EQ(c.size(), a.size());
  EXPECT_EQ(std::memcmp(a.data(), c.data(), a.size() * sizeof(ChunkPoint)), 0);
  const Status again = loadChunk(held[0], c);
  EXPECT_FALSE(again.isOk()) << "a held chunk is handed over once";
  // Pass A's rewrite: fewer records (outliers dropped), saved and loaded again.
  a.resize(a.size() - 7);
  a[0].vid = 12345;
  ChunkRecords rewritten = a;
  held[0].count = rewritten.size();
  ASSERT_TRUE(saveChunk(held[0], std::move(rewritten)).isOk());
  ASSERT_TRUE(loadChunk(held[0], c).isOk());
  ASSERT_EQ(c.size(), a.size());
  EXPECT_EQ(std::memcmp(a.data(), c.data(), a.size() * sizeof(ChunkPoint)), 0);
  distribute("over", true, 1024, over);
  ASSERT_GT(over.size(), 1u);
  for (const ChunkInfo& ch : over) EXPECT_EQ(ch.held, nullptr) << "more than one chunk: files";
}

}  // namespace
}  // namespace sa
