// The points baseline's data: the pack's source files (NOTE section, docs/FORMAT.md) read
// again and turned into float offsets from the pack origin plus RGBA8 colours.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "atlas/pack_file.h"

namespace sa {

struct SourcePoints {
  std::vector<float> xyz;     // relative to the pack origin
  std::vector<uint8_t> rgba;  // white when the source has no colour
};

Status loadSourcePoints(const PackReader& pack, SourcePoints& out);

class Renderer;
// Reads the pack's sources and hands them to the renderer's points baseline.
Status uploadSourcePoints(const PackReader& pack, Renderer& renderer);

}  // namespace sa
