// Large allocations backed by transparent huge pages (common/huge_pages.h, common/huge_new.cpp).
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "common/huge_pages.h"

namespace sa {
namespace {

// The kernel's THP mode: "always", "madvise" or "never" (the bracketed word); empty without THP.
std::string thpMode() {
  std::ifstream in("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t a = all.find('['), b = all.find(']');
  return a == std::string::npos || b == std::string::npos ? "" : all.substr(a + 1, b - a - 1);
}

// AnonHugePages (kB) of the mapping that holds p, from /proc/self/smaps; -1 when none holds it.
// madvise splits a mapping where the advised range begins: ask about an address well inside it.
long hugeKb(const void* p) {
  std::ifstream in("/proc/self/smaps");
  const uintptr_t at = reinterpret_cast<uintptr_t>(p);
  std::string line;
  bool inside = false;
  while (std::getline(in, line)) {
    uintptr_t lo = 0, hi = 0;
    char dash = 0;
    std::istringstream head(line);
    if (head >> std::hex >> lo >> dash >> hi && dash == '-') {
      inside = lo <= at && at < hi;
      continue;
    }
    if (inside && line.rfind("AnonHugePages:", 0) == 0) return std::stol(line.substr(14));
  }
  return -1;
}

TEST(HugePages, AdvisedBlocksAreBackedByHugePages) {
  const std::string mode = thpMode();
  if (mode != "madvise" && mode != "always") GTEST_SKIP() << "transparent huge pages are '" << mode << "' here";
  const size_t n = size_t(32) << 20;
  void* p = std::malloc(n);
  ASSERT_NE(p, nullptr);
  EXPECT_TRUE(adviseHugePages(p, n));
  std::memset(p, 1, n);
  EXPECT_GT(hugeKb(static_cast<uint8_t*>(p) + n / 2), 0) << "THP mode " << mode;
  std::free(p);
  // A block that holds no whole 2 MiB page is left alone.
  alignas(64) static uint8_t small[4096];
  EXPECT_FALSE(adviseHugePages(small, sizeof small));
}

// The scanatlas binary's operator new (common/huge_new.cpp, linked into this test too) advises
// large blocks itself: without it a 32 MiB vector under "madvise" gets no huge page.
TEST(HugePages, TheProgramsOperatorNewAdvisesLargeBlocks) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "the sanitizer's runtime replaces operator new (huge_new.cpp leaves it alone)";
#endif
  const std::string mode = thpMode();
  if (mode != "madvise" && mode != "always") GTEST_SKIP() << "transparent huge pages are '" << mode << "' here";
  std::vector<uint8_t> v(size_t(32) << 20, 1);
  EXPECT_GT(hugeKb(v.data() + v.size() / 2), 0) << "THP mode " << mode;
}

}  // namespace
}  // namespace sa
