// scanatlas: the single binary. Subcommands live in cmd_*.cpp; only cli/ prints and picks
// exit codes (0 ok, 2 bad input or usage, 1 internal failure).
#include <cstdio>
#include <cstring>
#include <exception>
#include <new>
#include <string>

#include "cli/commands.h"

namespace {

const char* kUsage =
    "scanatlas — pack huge range scans into height-field atlases and ray-cast them per pixel\n"
    "\n"
    "usage: scanatlas <command> [options]\n"
    "\n"
    "commands:\n"
    "  pack    convert scans into a pack file (.hfa): PLY, Stanford .conf scan sets, PCD, Draco,\n"
    "          LAS, OBJ/OFF/STL, XYZ/PTS/CSV/TXT, several at once\n"
    "  convert write the points of any of those inputs as binary PLY, Draco or text\n"
    "  view    the interactive window (a scan is packed into a cache beside it first)\n"
    "  render  render views of a pack headless to PNG (and depth to PFM)\n"
    "  info    describe a pack (cells, levels, texels, bytes, bounds, timings) or input files\n"
    "          (format, points, attributes, bounds)\n"
    "  verify  check a pack completely: checksums, tile layout, gutters, frames, counts\n"
    "  bake    add what a surface-detail mode needs (e.g. --mode exact) to an existing pack\n"
    "  grooves find cracks and joints in a scan's points; export them as JSON / CSV\n"
    "  bench   frame times over a camera path, per mode and setting (GPU and CPU time, boxes, fragments)\n"
    "  eval    image error against a reference mesh or scan set, with frame times; trade-off plot\n"
    "\n"
    "Run 'scanatlas <command> --help' for a command's options.\n";

}  // namespace

namespace sa {

int reportError(const Status& s) {
  std::fprintf(stderr, "scanatlas: error: %s\n", s.message().c_str());
  // Damaged packs: point at the full check.
  if (s.message().find(".hfa: ") != std::string::npos &&
      (s.message().find("corrupt") != std::string::npos || s.message().find("truncated") != std::string::npos))
    std::fprintf(stderr, "scanatlas: run 'scanatlas verify' on the pack for a full report\n");
  return s.kind() == ErrorKind::kBadInput ? 2 : 1;
}

std::string jsonEscape(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '"': o += "\\\""; break;
      case '\\': o += "\\\\"; break;
      case '\n': o += "\\n"; break;
      case '\t': o += "\\t"; break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          char b[8];
          std::snprintf(b, sizeof(b), "\\u%04x", c);
          o += b;
        } else {
          o += c;
        }
    }
  }
  return o;
}

}  // namespace sa

int main(int argc, char** argv) {
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h") || !std::strcmp(argv[1], "help")) {
    std::fputs(kUsage, argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  if (!std::strcmp(argv[1], "--version")) {
    std::puts("scanatlas 0.1.0 (pack format 1)");
    return 0;
  }
  const std::string cmd = argv[1];
  int (*fn)(int, char**) = nullptr;
  if (cmd == "pack") fn = sa::cmdPack;
  if (cmd == "render") fn = sa::cmdRender;
  if (cmd == "view") fn = sa::cmdView;
  if (cmd == "info") fn = sa::cmdInfo;
  if (cmd == "convert") fn = sa::cmdConvert;
  if (cmd == "verify") fn = sa::cmdVerify;
  if (cmd == "bench") fn = sa::cmdBench;
  if (cmd == "eval") fn = sa::cmdEval;
  if (cmd == "bake") fn = sa::cmdBake;
  if (cmd == "grooves") fn = sa::cmdGrooves;
  if (fn) {
    // Last line of defence: an exception escaping a library is an internal failure with a
    // message, never an abort. (Outputs are temporaries until committed, so nothing
    // half-written remains.)
    try {
      return fn(argc - 2, argv + 2);
    } catch (const std::bad_alloc&) {
      std::fprintf(stderr, "scanatlas: error: %s: out of memory\n", cmd.c_str());
      return 1;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "scanatlas: error: %s: internal failure: %s\n", cmd.c_str(), e.what());
      return 1;
    }
  }
  std::fprintf(stderr, "scanatlas: unknown command '%s'\n\n%s", cmd.c_str(), kUsage);
  return 2;
}
