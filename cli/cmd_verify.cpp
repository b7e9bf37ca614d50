#include <cstdio>

#include "atlas/verify.h"
#include "cli/args.h"
#include "cli/commands.h"

namespace sa {

int cmdVerify(int argc, char** argv) {
  Args a;
  Status s = a.parse(argc, argv, {}, {"json", "help"}, {{"h", "help"}});
  if (a.flag("help")) {
    std::fputs("usage: scanatlas verify PACK [--json]\n\n"
               "Checks a pack completely: the checksum of every section, tiles inside their pages and\n"
               "never overlapping (gutters included), gutters repeating their tile's edge texels, frames\n"
               "orthonormal and right-handed, counts consistent with the header. Exit 0 when sound, 2 when\n"
               "anything is wrong (each problem is listed).\n",
               stdout);
    return 0;
  }
  if (!s) return reportError(s);
  if (a.positionals().size() != 1) return reportError(Status::badInput("verify: give exactly one pack"));
  PackReader pack;
  s = pack.open(a.positionals()[0]);
  if (!s) return reportError(s);
  const VerifyReport r = verifyPack(pack);
  if (a.flag("json")) {
    std::printf("{\"file\": \"%s\", \"ok\": %s, \"cells_checked\": %llu, \"gutter_texels_checked\": %llu, \"problems\": [",
                jsonEscape(pack.path()).c_str(), r.problems.empty() ? "true" : "false",
                (unsigned long long)r.cellsChecked, (unsigned long long)r.texelsChecked);
    for (size_t i = 0; i < r.problems.size(); ++i) std::printf("%s\"%s\"", i ? ", " : "", jsonEscape(r.problems[i]).c_str());
    std::printf("]}\n");
  } else if (r.problems.empty()) {
    std::printf("%s: OK (%llu cell%s, %llu gutter texel%s, every checksum)\n", pack.path().c_str(),
                (unsigned long long)r.cellsChecked, r.cellsChecked == 1 ? "" : "s", (unsigned long long)r.texelsChecked,
                r.texelsChecked == 1 ? "" : "s");
  } else {
    for (const auto& p : r.problems) std::fprintf(stderr, "%s: %s\n", pack.path().c_str(), p.c_str());
  }
  return r.problems.empty() ? 0 : 2;
}

}  // namespace sa
