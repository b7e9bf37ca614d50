#include "formats/mesh_openmesh.h"
#include "fuzz/fuzz_util.h"

// OBJ, OFF and STL through OpenMesh (after ScanAtlas's OFF count check): each input is tried
// under all three extensions, in process (production runs OpenMesh in a child, see
// formats/mesh_openmesh.h; scripts/fuzz.sh runs this target with -fork and -ignore_crashes
// for OpenMesh's own assertions, and fails on crashes in ScanAtlas frames).
extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  for (const char* ext : {".off", ".obj", ".stl"}) {
    const std::string path = sa::fuzz::writeInput(data, size, ext);
    sa::fuzz::NullSink sink;
    (void)sa::readMeshInProcess(path, 64, true, sink);
  }
  return 0;
}
