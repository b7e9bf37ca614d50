#include "modes/pack_sources.h"

#include <filesystem>

namespace sa {

Result<InputSet> openPackSources(const PackReader& pack, const std::string& why) {
  std::string columns;
  const auto sources = packSources(pack, columns);
  if (sources.empty()) return Status::badInput(pack.path() + ": the pack names no source files (NOTE); " + why);
  for (const auto& s : sources)
    if (!std::filesystem::exists(s)) return Status::badInput(pack.path() + ": source file " + s + " is gone; " + why);
  return InputSet::open(sources, columns);
}

}  // namespace sa
