#include "formats/conf.h"
#include "formats/text.h"
#include "fuzz/fuzz_util.h"

// Text clouds and .conf scan sets: both line-oriented text.
extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = sa::fuzz::writeInput(data, size, ".xyz");
  sa::fuzz::NullSink sink;
  auto layout = sa::readTextLayout(path, "");
  if (layout) (void)sa::readText(path, *layout, 64, sink);
  (void)sa::readConf(path);
  return 0;
}
