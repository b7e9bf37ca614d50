#include "cli/args.h"

#include <gtest/gtest.h>

namespace sa {
namespace {

TEST(Args, ValuesFlagsAndNegativeNumbers) {
  const char* argv[] = {"in.hfa", "--eye=-0.1,0.2,0.3", "--target", "-1,-2,-3", "-o", "a.png", "--quiet", "--size", "64x32"};
  Args a;
  Status s = a.parse(9, const_cast<char**>(argv), {"eye", "target", "output", "size"}, {"quiet"}, {{"o", "output"}});
  ASSERT_TRUE(s.isOk()) << s.message();
  EXPECT_EQ(a.positionals(), std::vector<std::string>{"in.hfa"});
  EXPECT_EQ(a.get("eye"), "-0.1,0.2,0.3");
  EXPECT_EQ(a.get("target"), "-1,-2,-3");
  EXPECT_EQ(a.get("output"), "a.png");
  EXPECT_TRUE(a.flag("quiet"));
  auto eye = parseVec3("eye", a.get("eye"));
  ASSERT_TRUE(eye.isOk());
  EXPECT_DOUBLE_EQ(eye->x(), -0.1);
  int w, h;
  ASSERT_TRUE(parseWxH("size", a.get("size"), w, h).isOk());
  EXPECT_EQ(w, 64);
  EXPECT_EQ(h, 32);
}

TEST(Args, UnknownOptionsAndMissingValuesAreErrors) {
  const char* a1[] = {"--bogus"};
  Args a;
  EXPECT_FALSE(a.parse(1, const_cast<char**>(a1), {}, {}).isOk());
  const char* a2[] = {"--eye"};
  Args b;
  EXPECT_FALSE(b.parse(1, const_cast<char**>(a2), {"eye"}, {}).isOk());
  const char* a3[] = {"--quiet=1"};
  Args c;
  EXPECT_FALSE(c.parse(1, const_cast<char**>(a3), {}, {"quiet"}).isOk());
}

TEST(Args, SizesWithSuffixes) {
  EXPECT_EQ(*parseSize("m", "512M"), 512ull << 20);
  EXPECT_EQ(*parseSize("m", "16M"), 16ull << 20);
  EXPECT_EQ(*parseSize("m", "1G"), 1ull << 30);
  EXPECT_EQ(*parseSize("m", "64Mi"), 64ull << 20);
  EXPECT_EQ(*parseSize("m", "1.5K"), 1536u);
  EXPECT_EQ(*parseSize("m", "4096"), 4096u);
  EXPECT_FALSE(parseSize("m", "12Q").isOk());
  EXPECT_FALSE(parseSize("m", "-1G").isOk());
  EXPECT_FALSE(parseSize("m", "").isOk());
  EXPECT_FALSE(parseVec3("eye", "1,2").isOk());
  EXPECT_FALSE(parseVec3("eye", "1,2,x").isOk());
  int w, h;
  EXPECT_FALSE(parseWxH("size", "0x10", w, h).isOk());
}

}  // namespace
}  // namespace sa
