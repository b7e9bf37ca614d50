// The files a pack was made from (its NOTE), opened again: what the modes that read the raw data
// (gdm's implicit surfaces, grooves' detection, the points baseline) start from.
#pragma once
#include <string>

#include "atlas/pack_file.h"
#include "common/error.h"
#include "formats/source.h"

namespace sa {

// Opens the pack's sources with the columns it was packed with; a clear error naming the pack
// when it names none or one is gone. why: what needs them ("gdm builds its voxels from them").
Result<InputSet> openPackSources(const PackReader& pack, const std::string& why);

}  // namespace sa
