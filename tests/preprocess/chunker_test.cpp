// Chunk files (preprocess/chunker.cpp): frames of byte-shuffled, zstd-compressed records. A chunk
// round-trips exactly (several frames, a frame's worth plus one), is smaller than its raw records,
// and a truncated, damaged or over-long file is an error naming it, never points made up.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <random>

#include "../common/test_util.h"
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
  std::vector<ChunkPoint> back;
  ASSERT_TRUE(loadChunk(c, back).isOk());
  ASSERT_EQ(back.size(), pts.size());
  EXPECT_EQ(std::memcmp(back.data(), pts.data(), pts.size() * sizeof(ChunkPoint)), 0);
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
    std::vector<ChunkPoint> back;
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
    const uint32_t head[2] = {0xffffffffu, 12};
    std::fwrite(head, 4, 2, f);
    std::fclose(f);
    expectError(dir.file("huge.bin"), 10, "a frame header claiming 4 billion records");
  }
  expectError(dir.file("missing.bin"), 10, "missing file");
}

}  // namespace
}  // namespace sa
