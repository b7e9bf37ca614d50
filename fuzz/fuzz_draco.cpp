#include "formats/draco.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = sa::fuzz::writeInput(data, size, ".drc");
  sa::fuzz::NullSink sink;
  // In process, so libFuzzer sees libdraco's coverage. Production decodes in a child process
  // (readDraco); scripts/fuzz.sh runs this target with -fork and -ignore_ooms because libdraco
  // itself allocates gigabytes for some small hostile inputs.
  (void)sa::readDracoInProcess(path, 64, true, sink);
  return 0;
}
