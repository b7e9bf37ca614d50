#include "formats/ply.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = sa::fuzz::writeInput(data, size, ".ply");
  sa::fuzz::NullSink sink;
  sa::PlyReadOptions opt;
  opt.batchPoints = 64;
  (void)sa::readPly(path, opt, sink);
  opt.rangeGridTriangles = true;
  (void)sa::readPly(path, opt, sink);
  return 0;
}
