// Packing a real scan for a test: the opening lines of every test that runs on ../shared/data.
#pragma once
#include <string>

#include "atlas/pack_file.h"
#include "preprocess/pipeline.h"
#include "test_util.h"

namespace sa::test {

// Packs ../shared/data/<source> with default options into dir/<name>.hfa and opens it.
inline Status packShared(const TempDir& dir, const std::string& source, PackReader& pack, const std::string& name = "p") {
  if (!haveSharedData()) return Status::badInput("../shared/data is missing");
  auto input = InputSet::open({sharedData(source)});
  if (!input.isOk()) return input.status();
  PackSummary sum;
  SA_RETURN_IF_ERROR(packInput(*input, dir.file(name + ".hfa"), PackOptions{}, nullptr, sum));
  return pack.open(dir.file(name + ".hfa"));
}

}  // namespace sa::test
