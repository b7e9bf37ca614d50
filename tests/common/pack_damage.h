// Damaged copies of a pack for tests of how readers fail: one cell's coded tile overwritten.
#pragma once
#include <algorithm>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "atlas/pack_format.h"

namespace sa::test {

// A copy of the pack at `path` with the coded heights (HGTZ) of cell `cell` overwritten, its
// index kept, as `out`: that tile fails to decode and every other one decodes. False when the
// pack has no such tile.
inline bool damageHeightTile(const std::string& path, uint32_t cell, const std::string& out) {
  std::ifstream in(path, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (bytes.size() < sizeof(PackHeader)) return false;
  PackHeader h;
  std::memcpy(&h, bytes.data(), sizeof h);
  bool damaged = false;
  for (uint32_t k = 0; k < h.sectionCount; ++k) {
    SectionEntry e;
    std::memcpy(&e, bytes.data() + h.sectionTableOffset + k * sizeof e, sizeof e);
    if (std::memcmp(e.id, "HGTZ", 4) != 0) continue;
    uint64_t at = 0, size = 0;
    std::memcpy(&at, bytes.data() + e.offset + 8 + 16 * uint64_t(cell), 8);
    std::memcpy(&size, bytes.data() + e.offset + 8 + 16 * uint64_t(cell) + 8, 8);
    if (size == 0 || at + size > e.size) return false;
    std::fill(bytes.begin() + long(e.offset + at), bytes.begin() + long(e.offset + at + size), char(0xa5));
    damaged = true;
  }
  std::ofstream(out, std::ios::binary).write(bytes.data(), long(bytes.size()));
  return damaged;
}

}  // namespace sa::test
