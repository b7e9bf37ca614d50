#include "formats/pcd.h"
#include "fuzz/fuzz_util.h"

// The PCD header check runs first; only inputs that pass it reach PCL's reader.
extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = sa::fuzz::writeInput(data, size, ".pcd");
  sa::fuzz::NullSink sink;
  (void)sa::readPcd(path, 64, sink);
  return 0;
}
