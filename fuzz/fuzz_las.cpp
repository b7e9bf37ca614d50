#include "formats/las.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = sa::fuzz::writeInput(data, size, ".las");
  sa::fuzz::NullSink sink;
  (void)sa::readLas(path, 64, sink);
  return 0;
}
