#include "atlas/pack_file.h"
#include "atlas/verify.h"
#include "fuzz/fuzz_util.h"

// The pack reader follows offsets from the file: every one must be bounds-checked.
extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = sa::fuzz::writeInput(data, size, ".hfa");
  sa::PackReader r;
  if (!r.open(path)) return 0;
  (void)sa::verifyPack(r);
  uint64_t sum = 0;
  for (const sa::CellRecord& c : r.cells())
    for (int j = -1; j <= int(c.tileH) && j < 8; ++j)
      for (int i = -1; i <= int(c.tileW) && i < 8; ++i) sum += r.texel(c, i, j);
  // Stored levels (MIPZ): their blobs' headers and frames are the file's too.
  for (uint32_t i = 0; i < r.cells().size() && i < 64; ++i)
    if (const uint32_t l = r.storedLevelAtMost(i, 31)) {
      sa::TileImage t;
      if (r.decodeStoredLevel(i, l, t)) sum += t.heights.empty() ? 0 : t.heights[0];
    }
  (void)r.note();
  return int(sum & 0);
}
