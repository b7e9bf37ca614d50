// The `grooves` mode's bake: the grooves a pack draws (detected in its sources' raw points, or a
// user's grooves JSON), laid out per cell as the GROO section (modes/grooves/groove_cast.h).
#pragma once
#include <string>

#include "atlas/pack_file.h"
#include "common/error.h"
#include "grooves/grooves.h"
#include "modes/registry.h"

namespace sa::grooves {

// The grooves to store: req.groovesFile's (those with a depth or a profile as they are, the
// others measured in the sources' points), else those detected in the sources' points.
Result<GrooveSet> groovesForPack(const PackReader& pack, const BakeRequest& req, std::string& how);

// The registry's bake (modes/registry.cpp).
Result<ExtraSection> bakeSection(const PackReader& pack, const BakeRequest& req, std::string& summary);

// The grooves stored in a pack (the GROO section's JSON); none when the pack has no section.
Result<GrooveSet> packGrooves(const PackReader& pack);

}  // namespace sa::grooves
