// Full structural check of a pack (scanatlas verify): every section checksum, tiles inside
// their pages and never overlapping (gutters included), gutters repeating the tile edges,
// frames orthonormal, boxes ordered, counts consistent with META.
#pragma once
#include <string>
#include <vector>

#include "atlas/pack_file.h"

namespace sa {

struct VerifyReport {
  std::vector<std::string> problems;  // empty: the pack is sound
  uint64_t sectionsChecked = 0, cellsChecked = 0, texelsChecked = 0;
};

VerifyReport verifyPack(const PackReader& pack);

}  // namespace sa
